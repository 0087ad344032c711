"""Run a few episodes of the random baseline on SapienBinEnv; write a video per episode next to a
printed log (question, pushes, what each push changed).

    python recipes/random_episodes.py episodes=3 env.difficulties=[hard] video_format=gif
    python recipes/random_episodes.py reward=local reward.simple_threshold=0.1
"""

from __future__ import annotations

import time
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.video import episode_frames, write_video
from mqa_rl.modules.random_policy import RandomMQAPolicy
from mqa_rl.transforms.mqa_env import make_mqa_env


def describe_step(t: int, td) -> str:
    """One log line: the action and what it changed (objects moved, target overlap)."""
    nxt = td["next"]
    mask = td[keys.OBJECT_MASK]
    moved = ((nxt[keys.OBJECT_POS] - td[keys.OBJECT_POS]).norm(dim=-1) > 0.005) & mask
    tgt = td[keys.TARGET_MASK]
    chi0 = td[keys.OVERLAP][tgt]
    chi1 = nxt[keys.OVERLAP][tgt]
    a = int(td[keys.ACTION])
    if a == actions.STOP:
        what = "stop"
    else:
        d, row, col = actions.decode(a)
        s, e = nxt[keys.PUSH_START].tolist(), nxt[keys.PUSH_END].tolist()
        what = (f"push {d * 45:>3}° from cell ({row:2d},{col:2d}) "
                f"({s[0]:+.3f},{s[1]:+.3f},{s[2]:.3f}) -> ({e[0]:+.3f},{e[1]:+.3f})")
    overlap = f"targets χ {chi0.mean():.2f} -> {chi1.mean():.2f}, visible {int((chi1 < 1).sum())}/{len(chi1)}" if len(chi1) else "no target in the bin"
    terms = nxt[keys.REWARD_TERMS]
    reward = f"reward {nxt[keys.REWARD].item():+.3f} (" + ", ".join(f"{k} {terms[k].item():+.3f}" for k in terms.keys()) + ")"
    return f"  step {t}: {what:<62} moved {int(moved.sum()):2d} objects; {overlap}\n           {reward}"


@hydra.main(config_path="conf", config_name="random_episodes", version_base="1.3")
def main(cfg: DictConfig) -> None:
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    env = make_mqa_env(cfg.dataset, cfg.reward, seed=cfg.seed, **OmegaConf.to_container(cfg.env))
    policy = RandomMQAPolicy(cfg.env.max_pushes, seed=cfg.seed)
    base = env.base_env
    lines = []
    for ep in range(cfg.episodes):
        t0 = time.perf_counter()
        with torch.no_grad():
            r = env.rollout(cfg.env.max_pushes + 1, policy)
        q = base.question
        lines.append(f"episode {ep}: {q.id} ({base.dataset.scene(q.scene_id).difficulty}) "
                     f"\"{q.text}\" answer {q.answer}; {r.shape[0]} steps in {time.perf_counter() - t0:.1f} s")
        lines += [describe_step(t, r[t]) for t in range(r.shape[0])]
        video = write_video(episode_frames(r, base.camera, q.text), out / f"episode_{ep}.{cfg.video_format}")
        lines.append(f"  video: {video}")
    lines.append(f"reward variant: {cfg.reward.get('name', 'custom')} {OmegaConf.to_container(cfg.reward)}")
    text = "\n".join(lines)
    (out / "episodes.log").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
