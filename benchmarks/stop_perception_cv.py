"""Does a learned stop that reads the counting perception stop better? (the countable chain's stop; run on an
earlier perception file, then again on the 448-px one)

The learned stop reads the push policy's geometry maps; refitted with their change since I_start and their gap below
the best so far appended, it stopped no better ("what the stop lacks is a better view of the targets"). The counting
perception (`checkpoints/vqa_counting/perception.pt`) is that view: per class, how many objects show above the
counter's line. This probe runs the policy's never-stopping episodes on the training split as `recipes/fit_stop.py`
does, keeps per state the stop features and the perception's reading of the asked class (expected count, count,
area, largest masses, all classes' count), then refits the stop critic 5-fold by scene with

  base           the shipped stop features
  +count         + the asked class's reading now
  +count+since   + its change since I_start and its gap below the best so far

and prints the share of targets the stopped frame leaves uncountable, the share of episodes where every target is
countable, and the differences to base paired by episode, bootstrapped by scene; and how often the perceived count
of the asked class rises after a push against how often the share a counter misses falls (its flicker). A perception
that reads a finer render (the shipped 448-px file) reads each state through the env's answer camera, as the VQA does.
The reading is ``PerceivedCount``'s, what ``recipes/fit_stop.py perception=<file>`` builds into the stop.

    python benchmarks/stop_perception_cv.py run=checkpoints/dqn_countable out=runs/stop/perception400 episodes=400
    python benchmarks/stop_perception_cv.py run=checkpoints/dqn_countable out=runs/stop/perception448 episodes=200   # 29 min
"""
from __future__ import annotations

import hashlib
import io
import sys
import time
from pathlib import Path

import torch
from omegaconf import OmegaConf

from mqa_rl import keys
from mqa_rl.data.dataset import LEVELS, MQADataset
from mqa_rl.evaluation.episode_metrics import scene_bootstrap_ci95
from mqa_rl.files import load_tensors, write_atomic
from mqa_rl.modules.learned_stop import policy_net, reading_env_kwargs, stop_features
from mqa_rl.modules.perceived_count import PerceivedCount, token_channels
from mqa_rl.modules.stop_margin import StopMargin
from mqa_rl.modules.trained_policy import load_greedy, read_run_config
from mqa_rl.training.optimal_stopping import fit_stop_critic, fixed_rules, stopped_chi
from mqa_rl.transforms.episode_stats import uncountable_share
from mqa_rl.transforms.mqa_env import make_mqa_env
from mqa_rl.transforms.push_memory import memory_radius

def padded(x: torch.Tensor, length: int) -> torch.Tensor:
    pad = length - x.shape[0]
    return torch.cat([x, x[-1:].expand(pad, *x.shape[1:])]) if pad > 0 else x[:length]


def collect(run: Path, perception: str, level: str, episodes: int, seed: int) -> dict:
    cfg = read_run_config(run)
    max_pushes = int(cfg.env.max_pushes)
    read = PerceivedCount.from_file(perception, token_channels(MQADataset(str(cfg.dataset))))
    env = make_mqa_env(str(cfg.dataset), OmegaConf.to_container(cfg.reward), split="train", difficulties=[level], max_pushes=max_pushes,
                       question_types=list(cfg.env.question_types), push_memory=memory_radius(None, cfg.env),
                       **reading_env_kwargs(read, int(cfg.env.image_size)))
    try:
        actor, _, _ = load_greedy(run, None, env)
        net = policy_net(actor)
        policy = StopMargin(actor, float("inf"))
        env.base_env.set_seed(seed)
        base, reading, missed, valid, scenes = [], [], [], [], []
        with torch.no_grad():
            for _ in range(episodes):
                rollout = env.rollout(max_pushes + 1, policy, break_when_any_done=True)
                if not bool(rollout[0].get(keys.TARGET_MASK).any()):
                    continue
                question = env.base_env.question
                steps = rollout.shape[0]
                base.append(padded(stop_features(net, rollout, max_pushes), max_pushes))
                reading.append(padded(read.read(rollout), max_pushes))
                miss = torch.cat([uncountable_share(rollout), uncountable_share(rollout["next"][-1:])])
                missed.append(padded(miss, max_pushes + 1))
                valid.append(torch.arange(max_pushes) < min(steps, max_pushes))
                scenes.append(question.scene_id)
    finally:
        env.close()
    return {"base": torch.stack(base), "reading": torch.stack(reading), "uncountable": torch.stack(missed),
            "valid": torch.stack(valid), "scenes": scenes}


def feature_sets(base: torch.Tensor, reading: torch.Tensor) -> dict:
    numbers = reading[..., [0, -3, -2]]                          # count, log area, expected count
    since_start = numbers - numbers[:, :1]
    below_best = torch.cummax(numbers, dim=1).values - numbers
    return {"base": base, "+count": torch.cat([base, reading], -1),
            "+count+since": torch.cat([base, reading, since_start, below_best], -1)}


def flicker(reading: torch.Tensor, uncountable: torch.Tensor, valid: torch.Tensor) -> str:
    """After how many pushes the perceived count rose, and in what share of those the counter's missed share fell
    (or rose) with it; the same for the pushes after which the count stayed."""
    count = reading[..., 0]
    pair = valid[:, 1:]                                           # both states of the pair acted in
    rise = (count[:, 1:] > count[:, :-1]) & pair
    stay = (count[:, 1:] == count[:, :-1]) & pair
    fell = uncountable[:, 1:valid.shape[1]] < uncountable[:, :valid.shape[1] - 1] - 1e-6
    worse = uncountable[:, 1:valid.shape[1]] > uncountable[:, :valid.shape[1] - 1] + 1e-6
    share = lambda m, w: float(w[m].float().mean()) if m.any() else float("nan")  # noqa: E731
    return (f"count rose after {int(rise.sum())} of {int(pair.sum())} pushes: missed share fell after {share(rise, fell):.2f}, "
            f"rose after {share(rise, worse):.2f}; count stayed: fell {share(stay, fell):.2f}, rose {share(stay, worse):.2f}")


def main(run: str, out: str, episodes: str = "400", perception: str = "checkpoints/vqa_counting/perception.pt",
         seed: str = "7", folds: int = 5) -> None:
    torch.set_num_threads(2)
    levels = {}
    for level in LEVELS:
        path = Path(out) / f"{level}.pt"
        if path.is_file():
            levels[level] = load_tensors(path, what="probe trajectories", hint="delete it to collect again")
            continue
        tick = time.time()
        levels[level] = collect(Path(run), perception, level, int(episodes), int(seed))
        buffer = io.BytesIO()
        torch.save(levels[level], buffer)
        write_atomic(path, buffer.getvalue())
        print(f"{level}: {len(levels[level]['scenes'])} episodes in {time.time() - tick:.0f} s", flush=True)
    data = {k: torch.cat([levels[lv][k] for lv in LEVELS]) for k in ("base", "reading", "uncountable", "valid")}
    scenes = [s for lv in LEVELS for s in levels[lv]["scenes"]]
    level_of = torch.cat([torch.full((len(levels[lv]["scenes"]),), i) for i, lv in enumerate(LEVELS)])
    fold = torch.tensor([int(hashlib.sha256(s.encode()).hexdigest(), 16) % int(folds) for s in scenes])
    scene_ids = torch.tensor([sorted(set(scenes)).index(s) for s in scenes])
    value, valid = data["uncountable"], data["valid"]
    print(f"{len(scenes)} episodes, {len(set(scenes))} scenes, {folds} folds by scene")
    stopped, complete = {}, {}
    for name, features in feature_sets(data["base"], data["reading"]).items():
        share = torch.zeros(len(scenes))
        for k in range(int(folds)):
            train, test = fold != k, fold == k
            critic, _ = fit_stop_critic(features[train], value[train], valid[train], seed=0)
            with torch.no_grad():
                stop = (critic(features[test]) >= 0) & valid[test]
            share[test] = stopped_chi(value[test], stop, valid[test])
        stopped[name], complete[name] = share, (share < 1e-6).float()
        print(f"{name:>14}: uncountable share " + " / ".join(f"{float(share[level_of == i].mean()):.3f}" for i in range(3))
              + ", every target countable " + " / ".join(f"{float(complete[name][level_of == i].mean()):.3f}" for i in range(3)),
              flush=True)
    for i, lv in enumerate(LEVELS):
        m = level_of == i
        rules = fixed_rules(value[m], valid[m])
        print(f"{lv}: stop at once {rules['after_0']:.3f}, never {rules[f'after_{valid.shape[1]}']:.3f}, "
              f"hindsight {rules['hindsight']:.3f}; {flicker(data['reading'][m], value[m], valid[m])}")
    for name in list(stopped)[1:]:
        for what, table in (("uncountable share", stopped), ("every target countable", complete)):
            diff = table[name] - table["base"]
            cells = []
            for i in range(3):
                m = level_of == i
                mean, low, high, _ = scene_bootstrap_ci95(diff[m], scene_ids[m])
                cells.append(f"{mean:+.3f} [{low:+.3f}, {high:+.3f}]")
            print(f"{name} − base, {what}: " + " / ".join(cells))


if __name__ == "__main__":
    main(**dict(a.split("=", 1) for a in sys.argv[1:]))
