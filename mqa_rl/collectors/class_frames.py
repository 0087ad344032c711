"""Frames for pretraining the push Q-network's recognition: renders labelled with per-cell classes.

Each episode resets the env on a random question of the split and makes a random number of random
pushes inside the action mask (uniform on 0 … ``max_pushes``), keeping every image: first images and
the disturbed piles that pushing makes, as the policy will see them. Labels come from the
simulator's segmentation (``SapienBinEnv.class_cells``); nothing the policy acts on is privileged.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.data.dataset import LEVELS
from mqa_rl.envs import actions
from mqa_rl.progress import Progress


def collect_class_frames(env, frames: int, *, max_pushes: int, seed: int = 0, progress: bool = True) -> TensorDict:
    """[frames] of ``RGB`` (uint8), ``DEPTH`` (float16, m), ``CLASS_CELLS`` (float16), ``SCENE`` (index
    into the env's dataset scenes) and ``LEVEL`` (index into ``LEVELS``) from ``env`` (a ``SapienBinEnv``)."""
    if frames < 1 or max_pushes < 0:
        raise ValueError(f"need frames ≥ 1 and max_pushes ≥ 0, got {frames} and {max_pushes}")
    generator = torch.Generator().manual_seed(seed)
    env.set_seed(seed)
    scene_index = {s.id: i for i, s in enumerate(env.dataset.scenes)}
    out = []
    bar = Progress(frames, "frames", unit="frame", disable=not progress)
    while len(out) < frames:
        td = env.reset()
        pushes = int(torch.randint(max_pushes + 1, (), generator=generator))
        for k in range(pushes + 1):
            out.append(TensorDict({
                keys.RGB: td[keys.RGB].clone(),
                keys.DEPTH: td[keys.DEPTH].to(torch.float16),
                keys.CLASS_CELLS: torch.from_numpy(env.class_cells()).to(torch.float16),
                keys.SCENE: torch.tensor(scene_index[env.question.scene_id]),
                keys.LEVEL: torch.tensor(LEVELS.index(env.dataset.scene(env.question.scene_id).difficulty)),
            }, batch_size=[]))
            bar.update(1)
            if len(out) == frames or k == pushes:
                break
            td = env.step(td.set(keys.ACTION, actions.random_push(td[keys.ACTION_MASK], generator)))["next"]
    bar.close()
    return torch.stack(out)
