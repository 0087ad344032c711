"""Which frame should the answer keep? Every frame of a kept-frame system's episodes, read once, then keeping rules
compared on the same episodes (paired by question, 95 % by scene).

``record``: a push policy's episodes (the budget: ``stop_margin=inf``) on one level, and per state of each episode the
counting perception's reading of the asked class (``PerceivedCount``: rounded count, cluster masses, log area,
expected count) with the targets a perfect counter sees in it; one file per level, written when the level is done.
``compare``: the perfect counter on the frame each rule keeps (COUNTING questions), against the shipped rule
(``FrameKeeper``: the largest expected count, the later frame on ties), the first frame (no manipulation), the last
and the best frame of the episode (a ceiling no rule that reads the frames alone can pass); and how often the
perception's own rounded count of the asked class is the answer on each rule's frame, or read over all the frames.

    python benchmarks/keeper_rules.py record --dataset data/mqa_val --level hard --episodes 100 --out runs/keeper64/val
    python benchmarks/keeper_rules.py compare runs/keeper64/val runs/keeper64/val_s124   # levels pooled over folders
    python benchmarks/keeper_rules.py compare runs/keeper65/val runs/keeper65/val_s124 \
        --against runs/keeper64/val runs/keeper64/val_s124     # two policies (record --run) on the same questions
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import argparse
import io
import math
from pathlib import Path

import torch
from omegaconf import OmegaConf

from mqa_rl import keys
from mqa_rl.data.dataset import MQADataset
from mqa_rl.evaluation.episode_metrics import COUNTING, scene_bootstrap_ci95
from mqa_rl.evaluation.policy_units import close_envs, unit_env
from mqa_rl.evaluation.rollouts import run_episodes
from mqa_rl.files import load_tensors, write_atomic
from mqa_rl.modules.kept_frame import EXPECTED, FrameKeeper, episode_states, last_argmax, reading_env_options
from mqa_rl.modules.perceived_count import READING
from mqa_rl.modules.vote_counting import MAX_COUNT
from mqa_rl.modules.stop_margin import StopMargin
from mqa_rl.modules.trained_policy import load_greedy, read_run_config
from mqa_rl.transforms.episode_stats import targets_in_view
from mqa_rl.transforms.push_memory import memory_radius

COUNT = READING.index("perceived_count")


def record(a) -> None:
    run_cfg = read_run_config(a.run)
    dataset = a.dataset or run_cfg.dataset
    max_pushes = int(run_cfg.env.max_pushes)
    reward = OmegaConf.to_container(run_cfg.reward)
    setup = {"dataset": str(dataset), "reward": reward, "split": a.split, "max_pushes": max_pushes, "pusher": "finger",
             "qtypes": list(run_cfg.env.question_types), "push_memory": memory_radius(None, run_cfg.env),
             "frames": reading_env_options({"kept_frame": a.perception}, {"image_size": int(run_cfg.env.image_size)},
                                           MQADataset(dataset))}
    env = unit_env(setup, a.level)
    env.base_env.set_seed(a.seed)                       # evaluate_policy.py's questions for the same seed
    policy, _, _ = load_greedy(Path(a.run), None, env)
    policy = StopMargin(policy, math.inf)
    keeper = FrameKeeper.from_file(a.perception, env.base_env.dataset)
    scene_index = {s.id: i for i, s in enumerate(env.base_env.dataset.scenes)}
    episodes = []

    def on_episode(i, rollout):
        states = episode_states(rollout)
        frames = torch.stack([keeper.reading.frames(s) for s in states])
        question = states[0].get(keys.QUESTION)
        episodes.append({"reading": keeper.reading(frames, question.expand(len(states), *question.shape)),
                         "seen": torch.stack([targets_in_view(s).sum(-1) for s in states]).reshape(-1),
                         "targets": states[0].get(keys.TARGET_MASK).sum(-1).reshape(()),
                         "counting": bool(states[0].get(keys.QUESTION_TYPE).reshape(()) == COUNTING),
                         "scene": scene_index[env.base_env.question.scene_id]})
        if (i + 1) % 25 == 0:
            print(f"  {a.level}: {i + 1} / {a.episodes} episodes", flush=True)

    try:
        run_episodes(env, policy, a.episodes, max_pushes=max_pushes, on_episode=on_episode)
    finally:
        close_envs()
    buffer = io.BytesIO()
    torch.save({"meta": {"dataset": str(Path(dataset).resolve()), "split": a.split, "level": a.level, "seed": a.seed,
                         "run": str(a.run), "perception": str(a.perception), "reading": list(READING)},
                "episodes": episodes}, buffer)
    write_atomic(Path(a.out) / f"{a.level}.pt", buffer.getvalue())
    print(f"written to {Path(a.out) / f'{a.level}.pt'}")


def shipped(r: torch.Tensor) -> int:
    """FrameKeeper's rule: the largest expected count, the later frame on ties."""
    return last_argmax(r[:, EXPECTED])


def confirmed(r: torch.Tensor) -> int:
    """The largest rounded count read in at least two frames (an outlier's over-count is not believed), the frame
    of that count with the largest expected count."""
    c = r[:, COUNT]
    ranked = c.sort(descending=True).values
    top = ranked[1] if len(ranked) > 1 else ranked[0]
    return last_argmax(torch.where(c >= top, r[:, EXPECTED], torch.full_like(c, -1.0)))


def smoothed(r: torch.Tensor) -> int:
    """The largest expected count averaged with its neighbouring frames' (a push changes a pile a little)."""
    e = r[:, EXPECTED]
    padded = torch.cat([e[:1], e, e[-1:]])
    return last_argmax((padded[:-2] + padded[1:-1] + padded[2:]) / 3)


def second(r: torch.Tensor) -> int:
    """The frame of the second-largest expected count (the largest may be an over-count), the later on ties."""
    e = r[:, EXPECTED]
    top = e.sort(descending=True).values[min(1, len(e) - 1)]
    return int(torch.nonzero(e == top).max())


def rounded(r: torch.Tensor) -> int:
    """The largest rounded count, the larger expected count on ties."""
    c, e = r[:, COUNT], r[:, EXPECTED]
    return last_argmax(torch.where(c >= c.max(), e, torch.full_like(e, -1.0)))


SHIPPED = "shipped: largest expected"
RULES = {"first (no manipulation)": lambda r: 0, "last": lambda r: len(r) - 1, SHIPPED: shipped,
         "largest rounded count": rounded, "confirmed in two frames": confirmed,
         "second-largest expected": second, "smoothed over neighbours": smoothed}


def readouts(r: torch.Tensor) -> dict[str, float]:
    """Counts read from the frames of one episode without choosing one: what a head reading several frames could use."""
    top3 = r[:, EXPECTED].sort(descending=True).values[:3]
    return {"median rounded count over the frames": float(r[:, COUNT].median()),
            "mean of the 3 largest expected, rounded": float(torch.round(top3.mean()))}


def recorded_levels(folders: list[str]) -> dict[str, list[dict]]:
    """Per level, the COUNTING episodes of the folders' record files, pooled in the folders' order."""
    paths = [p for p in (Path(f) / f"{lv}.pt" for lv in ("easy", "medium", "hard") for f in folders) if p.is_file()]
    empty = [f for f in folders if not any(p.parent == Path(f) for p in paths)]
    if empty:
        raise FileNotFoundError(f"no <level>.pt record file in {empty}: write them with keeper_rules.py record --out")
    out: dict[str, list[dict]] = {}
    for path in paths:
        blob = load_tensors(path, what="keeper_rules.py record file", hint="run keeper_rules.py record again")
        out.setdefault(path.stem, []).extend(e for e in blob["episodes"] if e["counting"])
    return out


def counter_on(episode: dict, frame: int | None) -> float:
    """1 when a perfect counter on frame ``frame`` of the episode (None: its best frame) is right."""
    seen, targets = episode["seen"], episode["targets"]
    return float((seen == targets).any()) if frame is None else float(seen[frame] == targets)


def compare_policies(a) -> None:
    """Two policies' recordings of the same questions (record with the same dataset, levels, episodes and seeds, the
    folders in the same order): the perfect counter on the shipped rule's frame, the best and the first, A − B."""
    ours, theirs = recorded_levels(a.folders), recorded_levels(a.against)
    common = [level for level in ours if level in theirs]
    if not common:
        raise ValueError(f"{a.folders} and --against {a.against} share no recorded level")
    for level in common:
        eps, base = ours[level], theirs[level]
        if len(eps) != len(base) or any((x["scene"], int(x["targets"])) != (y["scene"], int(y["targets"]))
                                         for x, y in zip(eps, base)):
            raise ValueError(f"{level}: {a.folders} and --against {a.against} hold different questions; record both "
                             "with the same --dataset, --episodes and --seed, and list the folders in the same order")
        scenes = torch.tensor([e["scene"] for e in eps])
        print(f"\n{level}: {len(eps)} COUNTING episodes over {len(scenes.unique())} scenes; A = {a.folders}, B = {a.against}")
        for name, frame in (("the shipped rule's frame", shipped), ("the best frame", None),
                            ("the first frame", RULES["first (no manipulation)"])):
            x, y = (torch.tensor([counter_on(e, None if frame is None else frame(e["reading"])) for e in side])
                    for side in (eps, base))
            mean, low, high, _ = scene_bootstrap_ci95(x - y, scenes)
            print(f"  perfect counter on {name:26s} A {x.mean():.3f}  B {y.mean():.3f}  A − B {mean:+.3f} [{low:+.3f}, {high:+.3f}]")


def compare(a) -> None:
    if a.against:
        return compare_policies(a)
    for level, eps in recorded_levels(a.folders).items():
        scenes = torch.tensor([e["scene"] for e in eps])
        answer = torch.tensor([min(int(e["targets"]), MAX_COUNT) for e in eps])
        frames = {name: [rule(e["reading"]) for e in eps] for name, rule in RULES.items()}
        counter = {name: torch.tensor([counter_on(e, i) for e, i in zip(eps, kept)]) for name, kept in frames.items()}
        read = {name: torch.tensor([float(min(int(e["reading"][i, COUNT]), MAX_COUNT) == t) for e, i, t in zip(eps, kept, answer)])
                for name, kept in frames.items()}
        for e, t in zip(eps, answer):
            for name, value in readouts(e["reading"]).items():
                read.setdefault(name, []).append(float(min(int(value), MAX_COUNT) == t))
        read = {k: torch.as_tensor(v) for k, v in read.items()}
        best = torch.tensor([counter_on(e, None) for e in eps])
        print(f"\n{level}: {len(eps)} COUNTING episodes over {len(scenes.unique())} scenes; a perfect counter on the best "
              f"frame of the episode {best.mean():.3f}\n  {'rule':40s} perfect counter on its frame − shipped [95 % by scene]"
              f" | perception's rounded count = answer − shipped")
        for name in read:
            cells = []
            for table in (counter, read):
                if name in table:
                    mean, low, high, _ = scene_bootstrap_ci95(table[name] - table[SHIPPED], scenes)
                    cells.append(f"{table[name].mean():.3f} {mean:+.3f} [{low:+.3f}, {high:+.3f}]")
                else:
                    cells.append(" " * 30)
            print(f"  {name:40s} " + " | ".join(cells))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("record", help="one level's episodes, every frame read")
    r.add_argument("--run", default="checkpoints/dqn_countable", help="a train_dqn.py output folder (the push policy)")
    r.add_argument("--perception", default="checkpoints/vqa_counting/perception.pt")
    r.add_argument("--dataset", default=None, help="default: the run's")
    r.add_argument("--split", default="test")
    r.add_argument("--level", required=True, choices=("easy", "medium", "hard"))
    r.add_argument("--episodes", type=int, default=100)
    r.add_argument("--seed", type=int, default=123, help="evaluate_policy.py's default: the same questions")
    r.add_argument("--out", required=True, help="a folder: <level>.pt is written there")
    c = sub.add_parser("compare", help="the rules on a folder of recorded levels")
    c.add_argument("folders", nargs="+", help="record --out folders; the same level's episodes are pooled")
    c.add_argument("--against", nargs="+", default=None,
                   help="another policy's record folders of the same questions: compare the policies, not the rules")
    a = p.parse_args()
    torch.set_num_threads(1)
    record(a) if a.command == "record" else compare(a)


if __name__ == "__main__":
    main()
