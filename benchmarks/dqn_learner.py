"""Learner cost of the push Q-network: one DQN update (double DQN, prioritized batch) per trunk, the
acting forward pass, and the replay bytes per transition. Synthetic batches with the env's shapes.

    python benchmarks/dqn_learner.py                          # light, efficientnet_lite0, resnet18, resnet101; batch 16
    python benchmarks/dqn_learner.py --trunks light --batch 16 32 --threads 2
    python benchmarks/dqn_learner.py --trunks light efficientnet_lite0 efficientnet_lite0_frozen --threads 2 --no-double-dqn
    python benchmarks/dqn_learner.py --device cuda --batch 16 64 256       # the paper-scale config on a GPU

End-to-end env steps/s of the training loop come from the recipe's own log (``time/env_steps_per_s``,
``time/updates_per_s``, ``time/loop_env_steps_per_s`` in ``csv/scalars``); ``--e2e DATASET`` runs short
trainings with 1 and 2 collector workers (and 1 asynchronous one) and prints them. ``--mask-effect
DATASET`` compares random pushes inside the action mask with random pushes anywhere (how often a push
moves anything: what ε-exploration gains from the mask).
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import argparse
import csv
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict
from torchrl.data import Categorical

from mqa_rl import keys
from mqa_rl.collectors.replay import compact_transitions, transition_bytes
from mqa_rl.envs import actions
from mqa_rl.losses.dqn import make_dqn_loss
from mqa_rl.modules.push.push_policy import make_push_qnet, make_q_actor
from mqa_rl.sim.geometry import BinSpec, CameraSpec

VOCAB, QLEN, SIZE = 120, 14, 224
CONF = Path(__file__).parents[1] / "recipes" / "conf" / "trunk"
MODELS = {p.stem: dict(OmegaConf.to_container(OmegaConf.load(p))) for p in sorted(CONF.glob("*.yaml"))}   # the recipe's
MODELS["light_full_res"] = {**MODELS["light"], "light_downsample": 1}                                     # for comparison
MODELS["light_recognition"] = {**MODELS["light"], "class_map": True}        # the students' recognition: rgb trunk frozen
MODELS["light_rotated"] = {**MODELS["light_recognition"], "rotated_head": True, "head_channels": [16, 16]}  # one head, 8 turns
MODELS["efficientnet_lite0_frozen"] = {**MODELS["efficientnet_lite0"], "freeze_trunk": True}   # ImageNet trunk, heads only


def fake_transitions(n: int, gen: torch.Generator) -> TensorDict:
    mask = actions.push_start_mask(BinSpec(), CameraSpec(), np.full((SIZE, SIZE), CameraSpec().distance))
    allowed = mask.nonzero().squeeze(-1)

    def obs():
        q = torch.randint(1, VOCAB, (n, QLEN), generator=gen)
        q[:, 10:] = 0
        return {keys.RGB: torch.randint(0, 256, (n, 3, SIZE, SIZE), dtype=torch.uint8, generator=gen),
                keys.DEPTH: 0.75 + 0.15 * torch.rand(n, 1, SIZE, SIZE, generator=gen),
                keys.QUESTION: q, keys.ACTION_MASK: mask.expand(n, -1).clone()}

    nxt = obs()
    nxt.update({keys.REWARD: torch.randn(n, 1, generator=gen), "done": torch.zeros(n, 1, dtype=torch.bool),
                "terminated": torch.zeros(n, 1, dtype=torch.bool), "truncated": torch.zeros(n, 1, dtype=torch.bool)})
    td = TensorDict({**obs(), keys.ACTION: allowed[torch.randint(len(allowed), (n,), generator=gen)], "next": nxt}, [n])
    td.set(keys.TARGET_CELLS, torch.rand(n, actions.GRID, actions.GRID, generator=gen))   # stored for the auxiliary loss
    return td


def wall(device: torch.device) -> float:
    """Wall-clock seconds once the device has finished its queued work (CUDA runs asynchronously)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()


def time_update(model: dict, batch: int, repeats: int, device: torch.device = torch.device("cpu"),
                double_dqn: bool = True) -> tuple[float, float]:
    """Median seconds of (one update, one acting forward of a single observation); ``double_dqn=False``: the
    paper's target (one forward pass fewer), as the paper and paper_cpu profiles train."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        net = make_push_qnet(model, vocab_size=VOCAB, camera_distance=0.9).to(device)
    if model.get("class_map") and model.get("pretrained_frozen", True):     # as after load_recognition
        for p in (*net.rgb_trunk.parameters(), *net.class_head.parameters()):
            p.requires_grad_(False)
    actor = make_q_actor(net, Categorical(actions.NUM_ACTIONS))
    loss, updater = make_dqn_loss(actor, {"gamma": 0.6, "function": "huber", "double_dqn": double_dqn})
    opt = torch.optim.Adam([p for p in loss.parameters() if p.requires_grad], lr=1e-4)
    gen = torch.Generator().manual_seed(0)
    data = compact_transitions(fake_transitions(batch, gen))
    data.set("priority_weight", torch.ones(batch))
    data = data.to(device)
    times, acts = [], []
    for i in range(repeats + 1):
        t0 = wall(device)
        out = loss(data.clone())
        opt.zero_grad()
        out["loss"].backward()
        opt.step()
        updater.step()
        if i:
            times.append(wall(device) - t0)
        with torch.no_grad():
            t0 = wall(device)
            actor(data[:1].clone())
            if i:
                acts.append(wall(device) - t0)
    return statistics.median(times), statistics.median(acts)


def e2e(dataset: str, frames: int) -> None:
    """Short training runs (smoke profile, but 10 pushes per episode and the default light trunk).

    Every collector gets the same learner work per frame (8 frames per batch, 4 updates of 16: 0.5
    updates per frame, the default's ratio), so the loops differ only in how they collect."""
    root = Path(__file__).parents[1]
    frames_per_batch, updates_per_batch = 8, 4
    for kind, workers in (("single", 1), ("multi_sync", 2), ("multi_async", 1)):
        with tempfile.TemporaryDirectory() as out:
            args = [sys.executable, str(root / "recipes" / "train_dqn.py"), "profile=smoke", f"dataset={dataset}",
                    f"out_dir={out}", f"collector={kind}", f"collector.num_workers={workers}",
                    f"collector.total_frames={frames}", f"collector.frames_per_batch={frames_per_batch}",
                    "env.max_pushes=10", "eval.episodes=1", f"eval.interval_frames={frames}",
                    f"checkpoint.interval_frames={frames}", "buffer.size=256", "buffer.batch_size=16",
                    f"loss.updates_per_batch={updates_per_batch}"]
            t0 = time.perf_counter()
            run = subprocess.run(args, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if run.returncode:
                print(run.stdout[-2000:], run.stderr[-3000:])
                continue
            rows = {}
            for name in ("time/env_steps_per_s", "time/updates_per_s", "time/loop_env_steps_per_s"):
                with open(Path(out) / "csv" / "scalars" / f"{name}.csv") as f:
                    rows[name] = [float(r[1]) for r in csv.reader(f)]
            print(f"{kind:>11} x{workers}: {frames} frames, {wall:.0f} s wall incl. start-up; collection "
                  f"{statistics.median(rows['time/env_steps_per_s']):.2f} env steps/s (median over batches), "
                  f"updates {statistics.median(rows['time/updates_per_s']):.2f}/s (batch 16), "
                  f"loop end to end {rows['time/loop_env_steps_per_s'][-1]:.2f} env steps/s "
                  f"({updates_per_batch / frames_per_batch:g} updates/frame)")


def mask_effect(dataset: str, pushes: int) -> None:
    """What the action mask changes for exploration: ε-random pushes with and without it (hard scenes)."""
    from mqa_rl.modules.push.random_policy import RandomMQAPolicy
    from mqa_rl.transforms.mqa_env import make_mqa_env

    reward = OmegaConf.to_container(OmegaConf.load(Path(__file__).parents[1] / "recipes/conf/reward/global_local.yaml"))
    env = make_mqa_env(dataset, reward, split=None, difficulties=["hard"], max_pushes=10, seed=0)
    for masked in (False, True):
        env.base_env.set_seed(0)
        policy = RandomMQAPolicy(10, seed=0, masked=masked)
        policy.max_pushes.fill_(10**6)                      # never stop: pushes only
        r_e = []
        while len(r_e) < pushes:
            ro = env.rollout(10, policy, break_when_any_done=True)
            r_e += ro["next", *keys.EXPLORATION].reshape(-1).tolist()
        r_e = torch.tensor(r_e[:pushes])
        print(f"random pushes {'inside the mask' if masked else 'anywhere (paper)':>16}: moved an object (R_e > 0.05) "
              f"in {(r_e > 0.05).float().mean():.0%} of {pushes}, mean R_e {r_e.mean():.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trunks", nargs="+", choices=sorted(MODELS),
                    default=["light", "light_recognition", "light_rotated", "light_full_res", "efficientnet_lite0",
                             "efficientnet_lite0_frozen", "resnet18", "resnet101"])
    ap.add_argument("--batch", nargs="+", type=int, default=[16])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=torch.get_num_threads())
    ap.add_argument("--device", default="cpu", help="where the learner runs (cuda: the GPU figures)")
    ap.add_argument("--no-double-dqn", action="store_true",
                    help="the paper's target (paper and paper_cpu profiles): 2 forward passes per update, not 3")
    ap.add_argument("--e2e", metavar="DATASET", help="also run the recipe briefly with 1 and 2 workers on DATASET")
    ap.add_argument("--e2e-frames", type=int, default=96)
    ap.add_argument("--mask-effect", metavar="DATASET", help="also compare random pushes with and without the mask")
    ap.add_argument("--mask-pushes", type=int, default=100)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    example = compact_transitions(fake_transitions(1, torch.Generator().manual_seed(0)))[0]
    b = transition_bytes(example)
    print(f"replay: {b / 1e3:.1f} kB per transition ({SIZE}² images) -> 4,000: {4000 * b / 2**30:.2f} GiB, "
          f"50,000: {50000 * b / 2**30:.1f} GiB (memmap on disk)")
    device = torch.device(args.device)
    print(f"{'single' if args.no_double_dqn else 'double'} DQN, torch threads: {torch.get_num_threads()}, device: "
          f"{torch.cuda.get_device_name(device) if device.type == 'cuda' else 'cpu'}")
    print(f"load average before: {os.getloadavg()[0]:.2f} (the machine is shared: timings vary with it)")
    for trunk in args.trunks:
        for batch in args.batch:
            if device.type == "cuda":
                torch.cuda.reset_peak_memory_stats(device)
            upd, act = time_update(MODELS[trunk], batch, args.repeats, device, double_dqn=not args.no_double_dqn)
            peak = f"   peak GPU memory {torch.cuda.max_memory_allocated(device) / 2**30:.2f} GiB" if device.type == "cuda" else ""
            print(f"{trunk:>10} batch {batch:3d}: update {upd * 1e3:8.1f} ms   acting forward (1 obs) {act * 1e3:7.1f} ms{peak}")
    if args.mask_effect:
        mask_effect(args.mask_effect, args.mask_pushes)
    if args.e2e:
        e2e(args.e2e, args.e2e_frames)


if __name__ == "__main__":
    main()
