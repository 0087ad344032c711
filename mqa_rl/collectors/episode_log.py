"""A few episodes of the random baseline for people to look at: a video per episode (each push drawn as an arrow)
and a log of what every push changed (objects moved, the targets' hidden fraction χ, the reward and its terms);
``python recipes/collect.py what=episodes``."""

from __future__ import annotations

import time
from pathlib import Path

import torch

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.video import episode_frames, write_video
from mqa_rl.modules.push.random_policy import RandomMQAPolicy
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


def random_episodes(out_dir, dataset, reward: dict, env_options: dict, *, episodes: int, seed: int,
                    video_format: str = "mp4") -> str:
    """``episodes`` episodes of the random baseline on ``dataset`` with the reward stack ``reward``: a video each
    (``out_dir/episode_<i>.<video_format>``) and their log (``out_dir/episodes.log``, also returned)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    env = make_mqa_env(dataset, reward, seed=seed, **env_options)
    max_pushes = int(env_options.get("max_pushes", 10))
    policy = RandomMQAPolicy(max_pushes, seed=seed)
    base = env.base_env
    lines = []
    try:
        for ep in range(episodes):
            t0 = time.perf_counter()
            with torch.no_grad():
                r = env.rollout(max_pushes + 1, policy)
            q = base.question
            lines.append(f"episode {ep}: {q.id} ({base.dataset.scene(q.scene_id).difficulty}) "
                         f"\"{q.text}\" answer {q.answer}; {r.shape[0]} steps in {time.perf_counter() - t0:.1f} s")
            lines += [describe_step(t, r[t]) for t in range(r.shape[0])]
            video = write_video(episode_frames(r, base.camera, q.text), out / f"episode_{ep}.{video_format}")
            lines.append(f"  video: {video}")
    finally:
        env.close()
    lines.append(f"reward variant: {reward.get('name', 'custom')} {reward}")
    text = "\n".join(lines)
    (out / "episodes.log").write_text(text + "\n")
    return text
