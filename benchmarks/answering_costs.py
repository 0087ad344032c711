"""What the answering pipeline costs on this machine: CPU seconds per rollout episode of each policy
(per level), per encoded frame, per VQA update (frozen: cached features; fine-tuned: images), per
encoder-pretraining update, and per answered test episode. CPU time (``time.process_time``, one torch
thread) rather than wall time, so that a busy machine gives usable figures: on 2 quiet cores with 2
workers, wall ≈ CPU / 2.

    python benchmarks/answering_costs.py --dataset data/mqa --episodes 3 --run runs/local
    python benchmarks/answering_costs.py --skip-rollouts --device cuda     # the learning steps on a GPU (wall s)
"""

from __future__ import annotations

import argparse
import time

import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import LEVELS
from mqa_rl.losses.encoder_pretraining import EncoderPretrainLoss
from mqa_rl.losses.vqa import VQALoss
from mqa_rl.modules.answering.vqa import VQAModel, vqa_module
from mqa_rl.modules.answering.vqa_encoder import FrameEncoder, PretrainHeads

DEVICE = torch.device("cpu")


def seconds(fn, repeat: int = 1) -> float:
    """Seconds per call, after one warm-up call: CPU seconds on the CPU, wall seconds (synchronised) on a GPU."""
    fn()
    if DEVICE.type == "cuda":
        torch.cuda.synchronize(DEVICE)
        t = time.perf_counter()
        for _ in range(repeat):
            fn()
        torch.cuda.synchronize(DEVICE)
        return (time.perf_counter() - t) / repeat
    t = time.process_time()
    for _ in range(repeat):
        fn()
    return (time.process_time() - t) / repeat


def rollout_costs(ds: MQADataset, specs: dict, episodes: int) -> None:
    from mqa_rl.collectors.rollouts import plan_questions, run_question_episode      # the simulator: CPU only
    from mqa_rl.envs.sapien_bin import SapienBinEnv
    from mqa_rl.modules.frozen_policies import make_frozen_policy

    env = SapienBinEnv(ds, split=None)
    env.reset()                                          # shader compile, once per process
    print("| policy | level | CPU s / episode | pushes / episode | CPU s / push step |\n|---|---|---|---|---|")
    for name, spec in specs.items():
        policy, exploration = make_frozen_policy(spec, env, env.max_pushes)
        for level in LEVELS:
            qs = plan_questions(ds, "train", ["counting"], [level], max_per_group=episodes, seed=1)
            pushes, t = 0, time.process_time()
            for i, q in enumerate(qs):
                r = run_question_episode(env, policy, exploration, q, max_pushes=env.max_pushes, slot=i)
                pushes += int(r[keys.PUSHES])
            sec = (time.process_time() - t) / len(qs)
            print(f"| {name} | {level} | {sec:.2f} | {pushes / len(qs):.1f} | {sec / max(pushes / len(qs), 1):.3f} |",
                  flush=True)


def learning_costs(ds: MQADataset) -> None:
    torch.manual_seed(0)
    unit = "s wall" if DEVICE.type == "cuda" else "s CPU"
    img = torch.randint(0, 256, (64, 3, 224, 224), dtype=torch.uint8, device=DEVICE)
    model = VQAModel(ds.vocab.itos, ds.answers).eval().to(DEVICE)
    with torch.no_grad():
        encode = seconds(lambda: model.encode_frames(img)) / 64
    print(f"encode one frame (frozen encoder, no grad, batch 64): {encode * 1e3:.2f} m{unit}")
    q = torch.tensor([list(ds.questions[0].tokens)] * 64, device=DEVICE)
    labels = torch.zeros(64, dtype=torch.int64, device=DEVICE)
    for pool in ("eqa", "classes"):
        model = VQAModel(ds.vocab.itos, ds.answers, pool=pool).train().to(DEVICE)
        feats = model.encode_frames(img).detach()
        loss = VQALoss(vqa_module(model, from_features=True))
        batch = TensorDict({keys.QUESTION: q, keys.FIRST_FEATURES: feats, keys.LAST_FEATURES: feats,
                            keys.ANSWER_LABEL: labels}, batch_size=[64])
        opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad])

        def step():
            opt.zero_grad()
            loss(batch)["loss_vqa"].backward()
            opt.step()

        print(f"VQA update, batch 64, frozen encoder ({pool}): {seconds(step, 10) * 1e3:.1f} m{unit}")
    model = VQAModel(ds.vocab.itos, ds.answers, freeze_encoder=False).train().to(DEVICE)
    loss = VQALoss(vqa_module(model))
    for n in (16, 64):     # the recipe's batch is 64
        batch = TensorDict({keys.QUESTION: q[:n], keys.FIRST_RGB: img[:n], keys.LAST_RGB: img[:n],
                            keys.ANSWER_LABEL: labels[:n]}, batch_size=[n])
        print(f"VQA update, batch {n}, fine-tuned encoder: "
              f"{seconds(lambda: loss(batch)['loss_vqa'].backward(), 2):.3f} {unit}")
    enc = FrameEncoder(num_classes=1 + len(ds.classes))
    pre = EncoderPretrainLoss(enc, PretrainHeads(32, 1 + len(ds.classes)), camera_distance=ds.camera.distance).to(DEVICE)
    for n in (16, 32):     # the recipe's batch is 32
        frames = TensorDict({keys.RGB: img[:n], keys.DEPTH: torch.full((n, 1, 224, 224), 1.8, device=DEVICE),
                             keys.CLASS_MAP: torch.zeros(n, 224, 224, dtype=torch.uint8, device=DEVICE),
                             keys.OBJECT_MAP: torch.zeros(n, 224, 224, dtype=torch.uint8, device=DEVICE)}, batch_size=[n])

        def pre_step():
            out = pre(frames)
            sum(v for k, v in out.items() if k.startswith("loss_")).backward()

        print(f"encoder pretraining update, batch {n}: {seconds(pre_step, 2):.3f} {unit}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default="data/mqa")
    p.add_argument("--episodes", type=int, default=3, help="COUNTING questions per level and policy")
    p.add_argument("--run", default=None, help="a train_dqn.py run for the greedy DQN policy")
    p.add_argument("--policies", default="none,random,privileged,dqn")
    p.add_argument("--skip-rollouts", action="store_true")
    p.add_argument("--device", default="cpu", help="where the learning steps run (cuda: wall seconds on the GPU)")
    a = p.parse_args()
    global DEVICE
    DEVICE = torch.device(a.device)
    torch.set_num_threads(1)
    ds = MQADataset(a.dataset)
    specs = {"none": {"kind": "none"}, "random": {"kind": "random"}, "privileged": {"kind": "privileged", "lookahead": 1}}
    if a.run:
        specs["dqn"] = {"kind": "dqn", "run": a.run}
    specs = {k: v for k, v in specs.items() if k in a.policies.split(",")}
    if not a.skip_rollouts:
        rollout_costs(ds, specs, a.episodes)
    learning_costs(ds)


if __name__ == "__main__":
    main()
