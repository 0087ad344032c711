"""Evaluate a trained push policy greedily against the random baseline on the test split.

    python recipes/evaluate_policy.py run=outputs/train_dqn/local/2026-11-22_09-00-00
    python recipes/evaluate_policy.py run=... policies=[greedy] episodes_per_level=3 video_episodes=3
    python recipes/evaluate_policy.py run=... pusher=arm      # the same policy pushing with the Panda arm
    python recipes/evaluate_policy.py run=... 'policies=[greedy,random,image_teacher]'   # + its teacher
    python recipes/evaluate_policy.py run=... split=train stop_margin=0.5   # choose a stop margin on training scenes
    python recipes/evaluate_policy.py run=... stop_critic=runs/stop/x    # stop learnt by recipes/fit_stop.py

Per level and policy, over the same questions (the env is seeded alike for every policy): mean
episode reward, pushes, fraction of episodes ending in a simple scene, change of the targets' mean
hidden fraction χ from the first to the last image, fraction of targets fully hidden at the end, the net
number of targets made countable (``countable_gain``: made countable − buried, per episode) and whether a
perfect counter reads the COUNTING answer from I_stop (``counter_stop``) or from either frame
(``counter_either``) — each with a 95 % interval; and greedy − each other policy (random, no_manipulation, ...)
paired by question. Writes
``results.json``, ``results.md``, the per-episode metrics (``episodes/<policy>_<level>.pt``) and
videos (Q maps beside the frames) to ``out_dir``. ``baseline_from=<an earlier out_dir>`` reuses that
evaluation's random episodes when they were run on the same questions (same dataset, split, seed,
episodes, push limit, question types, pusher): the χ metrics carry over, the reward only if the
reward config matches too (else it is left out).
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from mqa_rl.envs.qmap_overlay import qmap_episode_frames
from mqa_rl.envs.video import write_video
from mqa_rl.evaluation.episode_metrics import mean_ci95
from mqa_rl.evaluation.rollouts import run_episodes
from mqa_rl.files import load_tensors, write_atomic
from mqa_rl.modules.frozen_policies import make_frozen_policy
from mqa_rl.modules.learned_stop import LearnedStop
from mqa_rl.modules.random_policy import RandomMQAPolicy
from mqa_rl.modules.stop_margin import StopMargin
from mqa_rl.modules.trained_policy import load_greedy, read_run_config
from mqa_rl.transforms.mqa_env import make_mqa_env
from mqa_rl.transforms.push_memory import memory_radius

# References that read the simulator (never a learned policy), as frozen-policy specs: the least-visible-first
# oracle, the image teacher (its occluders and directions from visible pixels and depth alone; the students'
# teacher), and the image teacher whose push is refined by simulating its direction from the 8 neighbouring
# start cells (the shipped student's).
ORACLES = {"oracle": {"kind": "privileged", "lookahead": 1},
           "image_teacher": {"kind": "privileged", "lookahead": 1, "order": "visible_first", "geometry": "visible"},
           "refined_teacher": {"kind": "privileged", "lookahead": 1, "order": "visible_first", "geometry": "visible",
                               "refine_radius": 1}}
# the reference that never pushes: the first image is the last (what a policy's pushes are worth beside nothing)
NO_MANIPULATION = {"kind": "none"}
REPORTED = ("reward", "pushes", "final_simple", "chi_end", "chi_change", "hidden_end", "into_view", "out_of_view",
            "countable_gain", "counter_stop", "counter_either", "stopped")


def episodes_meta(cfg: DictConfig, dataset, level: str, qtypes, max_pushes: int, reward: dict,
                  push_memory: int | None = None) -> dict:
    """What makes two evaluations' episodes the same questions (and the same reward)."""
    return {"dataset": str(Path(dataset).resolve()), "split": cfg.split, "seed": int(cfg.seed), "level": level,
            "episodes": int(cfg.episodes_per_level), "max_pushes": max_pushes, "pusher": cfg.pusher,
            "question_types": list(qtypes) if qtypes else None, "reward": reward, "push_memory": push_memory}


def shown(stat: dict, sep: str = " ± ") -> str:
    """A mean with its 95 % half-width; the mean alone where there is no interval (one episode: n = 1)."""
    ci = stat["ci95"]
    return f"{stat['mean']:+.3f}" if ci != ci else f"{stat['mean']:+.3f}{sep}{ci:.3f}"


def reuse_baseline(folder, name: str, meta: dict) -> dict[str, torch.Tensor] | None:
    """The per-episode metrics of policy ``name`` from an earlier evaluation, if on the same questions."""
    path = Path(folder) / "episodes" / f"{name}_{meta['level']}.pt"
    if not path.is_file():
        return None
    saved = load_tensors(path, what="baseline episodes file", hint="delete it (or give another baseline_from=) to evaluate again")
    # the reward is checked below; the paper's random never reads the action mask, so PushMemory leaves it alone
    ignored = ("reward", "push_memory") if name == "random" else ("reward",)
    same = {k: v for k, v in meta.items() if k not in ignored}
    if {k: saved["meta"].get(k) for k in same} != same:
        print(f"  {path}: other questions or settings, not reused")
        return None
    metrics = dict(saved["metrics"])
    if saved["meta"].get("reward") != meta["reward"]:   # another reward config: its rewards don't compare
        metrics = {k: v for k, v in metrics.items() if k != "reward" and not k.startswith("term/")}
    print(f"  {name}: reused {path}")
    return metrics


@hydra.main(config_path="conf", config_name="evaluate_policy", version_base="1.3")
def main(cfg: DictConfig) -> None:
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if "greedy" in cfg.policies and not cfg.run:
        raise ValueError("the greedy policy needs run=<a recipes/train_dqn.py output folder>")
    if cfg.stop_margin is not None and cfg.stop_critic is not None:
        raise ValueError("stop_margin and stop_critic are two stopping rules: give one of them")
    run_cfg = read_run_config(cfg.run) if cfg.run else None
    dataset = cfg.dataset or (run_cfg.dataset if run_cfg else None)
    if dataset is None:
        raise ValueError("give dataset=... (or run=... to use the run's dataset)")
    reward = OmegaConf.to_container(run_cfg.reward) if run_cfg else OmegaConf.to_container(
        OmegaConf.load(Path(__file__).parent / "conf" / "reward" / "global_local.yaml"))
    max_pushes = int(run_cfg.env.max_pushes) if run_cfg else 10
    qtypes = cfg.question_types or (list(run_cfg.env.question_types) if run_cfg else None)
    threshold = float(reward.get("simple_threshold", 0.2))
    push_memory = memory_radius(cfg.push_memory, run_cfg.env if run_cfg else None)
    results, lines = {}, []
    for level in cfg.difficulties:
        env = make_mqa_env(str(dataset), reward, episode_stats=True, split=cfg.split, difficulties=[level],
                           question_types=qtypes, max_pushes=max_pushes, pusher=cfg.pusher, push_memory=push_memory)
        per_policy = {}
        meta = episodes_meta(cfg, dataset, level, qtypes, max_pushes, reward, push_memory)
        for name in cfg.policies:
            env.base_env.set_seed(cfg.seed)                 # the same questions for every policy
            on_episode = None
            reused = reuse_baseline(cfg.baseline_from, name, meta) if cfg.baseline_from and name != "greedy" else None
            if name == "greedy":
                policy, _, ckpt = load_greedy(Path(cfg.run), cfg.checkpoint, env)
                if cfg.stop_margin is not None:
                    policy = StopMargin(policy, float(cfg.stop_margin))
                if cfg.stop_critic is not None:
                    policy = LearnedStop.from_file(policy, cfg.stop_critic, max_pushes, push_memory)

                def on_episode(i, rollout, level=level):
                    if i < cfg.video_episodes:
                        frames = qmap_episode_frames(rollout, env.base_env.camera, env.base_env.question.text)
                        write_video(frames, out / "videos" / f"{level}_{i}.{cfg.video_format}")
            elif name in ("random", "random_masked"):
                policy = RandomMQAPolicy(max_pushes, seed=cfg.seed, masked=name == "random_masked")
            elif name in ORACLES or name == "no_manipulation":
                policy, _ = make_frozen_policy(ORACLES.get(name, NO_MANIPULATION), env.base_env, max_pushes)
            else:
                raise ValueError(f"unknown policy {name!r}; choose among greedy, random, random_masked, no_manipulation, "
                                 + ", ".join(ORACLES))
            m = reused if reused is not None else run_episodes(
                env, policy, cfg.episodes_per_level, max_pushes=max_pushes, simple_threshold=threshold, on_episode=on_episode)
            buffer = io.BytesIO()
            torch.save({"meta": meta, "metrics": m}, buffer)
            write_atomic(out / "episodes" / f"{name}_{level}.pt", buffer.getvalue())
            per_policy[name] = m
            nan = torch.full((cfg.episodes_per_level,), float("nan"))
            results.setdefault(level, {})[name] = {k: dict(zip(("mean", "ci95", "n"), mean_ci95(m.get(k, nan))))
                                                   for k in REPORTED}
            print(f"{level:>6} {name:>13}: " + ", ".join(f"{k} {shown(results[level][name][k], sep='±')}" for k in REPORTED),
                  flush=True)
        if "greedy" in per_policy:
            for base in (p for p in per_policy if p != "greedy"):
                diff = {k: dict(zip(("mean", "ci95", "n"), mean_ci95(per_policy["greedy"][k] - per_policy[base].get(k, nan))))
                        for k in REPORTED}
                results[level][f"greedy-{base}"] = diff
        env.close()
    for level, rows in results.items():
        lines.append(f"\n### {level}\n\n| policy | " + " | ".join(REPORTED) + " |\n|---|" + "---|" * len(REPORTED))
        for name, row in rows.items():
            lines.append(f"| {name} | " + " | ".join(f"{shown(row[k])} (n={row[k]['n']})" for k in REPORTED) + " |")
    for name, text in (("results.json", json.dumps(results, indent=2)), ("results.md", "\n".join(lines) + "\n"),
                       ("config.yaml", OmegaConf.to_yaml(cfg, resolve=True))):   # what these figures were measured with
        write_atomic(out / name, text)
    print("\n".join(lines))
    print(f"written to {out}")


if __name__ == "__main__":
    main()
