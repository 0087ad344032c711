"""Evaluate a trained push policy greedily against the random baseline on the test split.

    python recipes/evaluate_policy.py run=outputs/train_dqn/local/2026-11-22_09-00-00
    python recipes/evaluate_policy.py run=... policies=[greedy] episodes_per_level=3 video_episodes=3
    python recipes/evaluate_policy.py run=... pusher=arm      # the same policy pushing with the Panda arm

Per level and policy, over the same questions (the env is seeded alike for every policy): mean
episode reward, pushes, fraction of episodes ending in a simple scene, change of the targets' mean
hidden fraction χ from the first to the last image, fraction of targets fully hidden at the end —
each with a 95 % interval; and greedy − random differences paired by question. Writes
``results.json``, ``results.md`` and videos (Q maps beside the frames) to ``out_dir``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from mqa_rl.envs.factory import make_mqa_env
from mqa_rl.envs.qmap_overlay import qmap_episode_frames
from mqa_rl.envs.video import write_video
from mqa_rl.evaluation.episode_metrics import mean_ci95
from mqa_rl.evaluation.rollouts import run_episodes
from mqa_rl.modules.push_policy import load_greedy
from mqa_rl.modules.random_policy import RandomMQAPolicy

REPORTED = ("reward", "pushes", "final_simple", "chi_end", "chi_change", "hidden_end", "stopped")


@hydra.main(config_path="conf", config_name="evaluate_policy", version_base="1.3")
def main(cfg: DictConfig) -> None:
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if "greedy" in cfg.policies and not cfg.run:
        raise ValueError("the greedy policy needs run=<a recipes/train_dqn.py output folder>")
    run_cfg = OmegaConf.load(Path(cfg.run) / "config.yaml") if cfg.run else None
    dataset = cfg.dataset or (run_cfg.dataset if run_cfg else None)
    if dataset is None:
        raise ValueError("give dataset=... (or run=... to use the run's dataset)")
    reward = OmegaConf.to_container(run_cfg.reward) if run_cfg else OmegaConf.to_container(
        OmegaConf.load(Path(__file__).parent / "conf" / "reward" / "global_local.yaml"))
    max_pushes = int(run_cfg.env.max_pushes) if run_cfg else 10
    qtypes = cfg.question_types or (list(run_cfg.env.question_types) if run_cfg else None)
    threshold = float(reward.get("simple_threshold", 0.2))
    results, lines = {}, []
    for level in cfg.difficulties:
        env = make_mqa_env(str(dataset), reward, episode_stats=True, split=cfg.split, difficulties=[level],
                           question_types=qtypes, max_pushes=max_pushes, pusher=cfg.pusher)
        per_policy = {}
        for name in cfg.policies:
            env.base_env.set_seed(cfg.seed)                 # the same questions for every policy
            on_episode = None
            if name == "greedy":
                policy, _, ckpt = load_greedy(Path(cfg.run), cfg.checkpoint, env)

                def on_episode(i, rollout, level=level):
                    if i < cfg.video_episodes:
                        frames = qmap_episode_frames(rollout, env.base_env.camera, env.base_env.question.text)
                        write_video(frames, out / "videos" / f"{level}_{i}.{cfg.video_format}")
            elif name in ("random", "random_masked"):
                policy = RandomMQAPolicy(max_pushes, seed=cfg.seed, masked=name == "random_masked")
            else:
                raise ValueError(f"unknown policy {name!r}; choose among greedy, random, random_masked")
            m = run_episodes(env, policy, cfg.episodes_per_level, max_pushes=max_pushes, simple_threshold=threshold,
                             on_episode=on_episode)
            per_policy[name] = m
            results.setdefault(level, {})[name] = {k: dict(zip(("mean", "ci95", "n"), mean_ci95(m[k]))) for k in REPORTED}
            print(f"{level:>6} {name:>13}: " + ", ".join(
                f"{k} {results[level][name][k]['mean']:+.3f}±{results[level][name][k]['ci95']:.3f}" for k in REPORTED),
                flush=True)
        if "greedy" in per_policy:
            for base in (p for p in per_policy if p != "greedy"):
                diff = {k: dict(zip(("mean", "ci95", "n"), mean_ci95(per_policy["greedy"][k] - per_policy[base][k])))
                        for k in REPORTED}
                results[level][f"greedy-{base}"] = diff
        env.close()
    for level, rows in results.items():
        lines.append(f"\n### {level}\n\n| policy | " + " | ".join(REPORTED) + " |\n|---|" + "---|" * len(REPORTED))
        for name, row in rows.items():
            lines.append(f"| {name} | " + " | ".join(f"{row[k]['mean']:+.3f} ± {row[k]['ci95']:.3f} (n={row[k]['n']})"
                                                   for k in REPORTED) + " |")
    for name, text in (("results.json", json.dumps(results, indent=2)), ("results.md", "\n".join(lines) + "\n")):
        tmp = out / f".{name}.tmp{os.getpid()}"
        tmp.write_text(text)
        os.replace(tmp, out / name)
    print("\n".join(lines))
    print(f"written to {out}")


if __name__ == "__main__":
    main()
