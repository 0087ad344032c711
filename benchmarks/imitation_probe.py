"""Can the push Q-network imitate the oracle's demonstrations at the CPU budget? A learnability probe.

Trains the Q-network (the light trunk with the pretrained recognition, as ``profile=cpu_recognition``
builds it) on the demonstrations of ``recipes/collect_demonstrations.py`` alone, with a supervised loss
on its Q map, and prints on held-out demonstrations how often the greedy push is the oracle's, is "near"
it (same direction, start within 3 cells), and starts within 2 cells of a visible target (random pushes
inside the mask: the base rate, printed first).

    python benchmarks/imitation_probe.py --loss ce_push --steps 1000        # cross-entropy over pushes
    python benchmarks/imitation_probe.py --loss margin --steps 1000         # DQfD's large margin
    python benchmarks/imitation_probe.py --demos runs/demos_image --smooth 1.5   # a soft target around the push
    python benchmarks/imitation_probe.py --demos runs/demos_image --smooth 1.5 --rotated   # one head, 8 rotations
    python benchmarks/imitation_probe.py --demos runs/demos_geometry --smooth 1.5 --true-targets  # perfect recognition
    python benchmarks/imitation_probe.py --demos runs/demos_geometry --smooth 1.5 --rotated --direction-weight 1.0
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from omegaconf import OmegaConf

sys.path.insert(0, str(Path(__file__).parents[1]))

from mqa_rl import keys  # noqa: E402
from mqa_rl.collectors.demonstrations import load_demonstrations  # noqa: E402
from mqa_rl.data import MQADataset  # noqa: E402
from mqa_rl.envs import actions  # noqa: E402
from mqa_rl.losses.demonstration import DemonstrationLoss, _near  # noqa: E402
from mqa_rl.modules.pretrained_recognition import load_recognition  # noqa: E402
from mqa_rl.modules.push_policy import make_push_qnet  # noqa: E402
from mqa_rl.transforms.dihedral import DihedralAugment  # noqa: E402

ROOT = Path(__file__).parents[1]


def near_target(pushes: torch.Tensor, target_cells: torch.Tensor, cells: int = 2) -> torch.Tensor:
    """Bool [N]: the push starts within ``cells`` grid cells of a cell showing a target (≥ 5 %)."""
    near = F.max_pool2d((target_cells.float() > 0.05).float()[:, None], 2 * cells + 1, 1, cells)[:, 0]
    per = actions.GRID ** 2
    return near[torch.arange(len(pushes)), (pushes % per) // actions.GRID, pushes % actions.GRID] > 0


def push_only(td):
    keep = td[keys.ACTION] != actions.STOP
    mask = td[keys.ACTION_MASK][keep].clone()
    mask[:, actions.STOP] = False
    return td[keep], mask


@torch.no_grad()
def scores(net, val, feed=None) -> tuple[float, float, float, float]:
    """Greedy push = the oracle's, near it, near a visible target; and the best direction at the oracle's
    start cell = its direction (chance 1/8): whether the head learns which way, apart from where."""
    val, mask = push_only(val)
    if feed is not None:
        feed(val)
    q = net(val[keys.RGB], val[keys.DEPTH], val[keys.QUESTION]).masked_fill(~mask, torch.finfo(torch.float32).min)
    greedy, demo = q.argmax(-1), val[keys.ACTION]
    per = actions.GRID ** 2
    cell = demo % per
    at_cell = q[:, : actions.NUM_PUSHES].view(-1, actions.DIRECTIONS, per)[torch.arange(len(demo)), :, cell]
    return (float((greedy == demo).float().mean()), float(_near(greedy, demo, 3).float().mean()),
            float(near_target(greedy, val[keys.TARGET_CELLS]).float().mean()),
            float((at_cell.argmax(-1) == demo // per).float().mean()))


class TrueTargets:
    """``--true-targets``: the class map's target map replaced by the simulator's visible-target cells of
    the batch (``target_cells``): is the direction learnable when recognition is perfect?"""

    def __init__(self, net):
        self.cells = None
        net._targets = lambda fr, qf: self.cells[:, None].to(fr.dtype)

    def __call__(self, batch):
        self.cells = batch[keys.TARGET_CELLS].float()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--demos", default=str(ROOT / "runs" / "demos"))
    ap.add_argument("--recognition", default=str(ROOT / "runs" / "recognition" / "recognition.pt"))
    ap.add_argument("--dataset", default=str(ROOT / "data" / "mqa"))
    ap.add_argument("--loss", choices=("ce_push", "margin"), default="ce_push")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--val", type=int, default=250)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--smooth", type=float, default=0.0, help="ce_push: Gaussian spread of the target in grid cells")
    ap.add_argument("--head-context", type=int, default=None, help="3x3 context convs in the head (light.yaml's: 2)")
    ap.add_argument("--rotated", action="store_true", help="one push head shared by the 8 directions (rotated_head)")
    ap.add_argument("--head-channels", type=int, nargs="+", default=None, help="head widths (light.yaml's: 32 16)")
    ap.add_argument("--true-targets", action="store_true", help="the simulator's target cells as the target map")
    ap.add_argument("--direction-weight", type=float, default=0.0,
                    help="plus this weight times the cross-entropy over the 8 directions at the demonstrated cell")
    args = ap.parse_args()
    torch.manual_seed(0)
    torch.set_num_threads(args.threads)
    ds = MQADataset(args.dataset)
    demos = load_demonstrations(args.demos, args.dataset)
    demos = demos[demos[keys.ACTION_MASK].gather(-1, demos[keys.ACTION][:, None]).squeeze(-1)]
    train, val = demos[: len(demos) - args.val], demos[len(demos) - args.val:]
    pushes, mask = push_only(val)
    random_pushes = torch.multinomial(mask.float(), 1).squeeze(-1)
    print(f"{len(train)} training / {len(val)} held-out demonstrations ({len(pushes)} pushes); random pushes inside the "
          f"mask start near a visible target in {float(near_target(random_pushes, pushes[keys.TARGET_CELLS]).float().mean()):.3f}")
    cfg = {**OmegaConf.to_container(OmegaConf.load(ROOT / "recipes" / "conf" / "trunk" / "light.yaml")), "class_map": True}
    if args.head_context is not None:
        cfg["head_context"] = args.head_context
    if args.rotated:
        cfg["rotated_head"] = True
    if args.head_channels:
        cfg["head_channels"] = args.head_channels
    net = make_push_qnet(cfg, vocab_size=len(ds.vocab), camera_distance=ds.camera.distance, num_classes=len(ds.classes))
    load_recognition(net, args.recognition, ds.classes)
    feed = TrueTargets(net) if args.true_targets else None
    optim = torch.optim.Adam([p for p in net.parameters() if p.requires_grad], lr=args.lr)
    margin, augment, t0 = DemonstrationLoss(net), DihedralAugment(), time.perf_counter()
    ce = DemonstrationLoss(net, "push_cross_entropy", smooth_cells=args.smooth, direction_weight=args.direction_weight)
    for step in range(1, args.steps + 1):
        batch = augment.forward(train[torch.randint(len(train), (16,))].clone())
        if feed is not None:
            feed(batch)
        if args.loss == "margin":
            loss = margin(batch)["loss_demo"]
        else:
            loss = ce(batch)["loss_demo"]
        optim.zero_grad()
        loss.backward()
        optim.step()
        if step % 100 == 0 or step == args.steps:
            same, near, target, direction = scores(net, val, feed)
            fit = scores(net, train[: args.val], feed)        # the same on training states: fitting or not at all
            print(f"{args.loss} step {step}: loss {loss.item():.3f}; held-out greedy push = oracle's {same:.3f}, near it "
                  f"{near:.3f}, near a visible target {target:.3f}; direction at its cell {direction:.3f} "
                  f"(training states: near {fit[1]:.3f}, direction {fit[3]:.3f}) ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
