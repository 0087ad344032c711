"""One episode played step by step for the page: a frame and a table row after every env step.

The loop is ``env.rollout``'s (reset, policy, step, ``step_mdp``) written out so that each step can be
shown while the next one runs. A frame shows the state before the step with its push drawn as an
arrow (``draw_push``), the state after it, and for a Q-network policy its Q map over the state it
decided on (``qmap_image``). The finished rollout goes through ``episode_frames`` /
``qmap_episode_frames`` and ``write_video``, as the recipes' videos do.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch
from torchrl.envs.utils import step_mdp

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.qmap_overlay import qmap_episode_frames, qmap_image
from mqa_rl.envs.video import annotate, draw_push, episode_frames

SCALE = 2
TERM_NAMES = {"exploration": "R_e", "global_occlusion": "R_g", "local_occlusion": "R_l", "simple_scene": "simple",
              "beta": "β"}
RECORDED = (keys.RGB, keys.ACTION_MASK, keys.ACTION, keys.ACTION_VALUE, ("next", keys.RGB), ("next", keys.IS_STOP),
            ("next", keys.PUSH_START), ("next", keys.PUSH_END))


@dataclass
class StepView:
    """What the page shows after a step (step 0: the first image, before any action)."""

    step: int
    frame: np.ndarray                         # RGB uint8
    row: dict                                 # the table row of this step
    done: bool = False
    rollout: object | None = None             # the whole episode (TensorDict [T]) on the last view
    first_rgb: torch.Tensor | None = None     # uint8 [H, W, 3], on the last view
    last_rgb: torch.Tensor | None = None
    tokens: torch.Tensor | None = None        # question tokens [L], on the last view
    answer_frames: tuple | None = None        # (I_start, I_stop) of the env's answer camera [S, S, 3], when it has one


def _hwc(rgb: torch.Tensor) -> np.ndarray:
    return np.ascontiguousarray(rgb.numpy().transpose(1, 2, 0))


def _side_by_side(panels: list[np.ndarray]) -> np.ndarray:
    """Panels next to each other, shorter ones padded with white on top (under the banners)."""
    height = max(p.shape[0] for p in panels)
    padded = [np.concatenate([np.full((height - p.shape[0], p.shape[1], 3), 255, np.uint8), p], 0) for p in panels]
    gap = np.full((height, 6, 3), 255, np.uint8)
    out = [padded[0]]
    for p in padded[1:]:
        out += [gap, p]
    return np.concatenate(out, 1)


def describe_action(action: int) -> str:
    if action == actions.STOP:
        return "stop"
    d, row, col = actions.decode(action)
    return f"push {45 * d}° from cell ({row}, {col})"


def table_row(step: int, td, action: int | None) -> dict:
    """Targets' visibility after the step and the reward terms of the step (td: the state shown)."""
    target = td[keys.TARGET_MASK]
    visible = (1 - td[keys.OVERLAP][target]).clamp(0, 1)
    row = {"step": step, "action": "first image" if action is None else describe_action(action),
           "targets": int(target.sum()),
           "targets seen": int((td[keys.VISIBLE_AREA][target] > 0).sum()),
           "visible (mean)": round(float(visible.mean()), 3) if len(visible) else None,
           "visible (min)": round(float(visible.min()), 3) if len(visible) else None}
    terms = td.get(keys.REWARD_TERMS, None)
    if terms is not None:
        for name in terms.keys():
            row[TERM_NAMES.get(name, name)] = None if action is None else round(float(terms[name]), 3)
    row["reward"] = round(float(td[keys.REWARD]), 3) if keys.REWARD in td.keys() and action is not None else None
    return row


def step_frame(before, after, camera, question: str, step: int) -> np.ndarray:
    """The state before a step with its push (or "stop"), the state after, and the Q map if any."""
    action = int(before[keys.ACTION])
    stop = action == actions.STOP
    left = annotate(_hwc(before[keys.RGB]), SCALE, [question, f"step {step}: " + ("stop" if stop else f"push {step + 1}")])
    if not stop:
        body = left[left.shape[0] - before[keys.RGB].shape[-2] * SCALE:]
        body[:] = draw_push(body, after[keys.PUSH_START].numpy(), after[keys.PUSH_END].numpy(), camera, SCALE)
    panels = [left]
    if not stop:
        panels.append(annotate(_hwc(after[keys.RGB]), SCALE, ["", f"after push {step + 1}"]))
    if keys.ACTION_VALUE in before.keys():
        panels.append(qmap_image(_hwc(before[keys.RGB]), before[keys.ACTION_VALUE], before[keys.ACTION_MASK], SCALE))
    return _side_by_side(panels)


@torch.no_grad()
def _act_and_step(env, policy, td):
    # grad mode is set per step, never across a yield: Gradio resumes the generator in any of its
    # worker threads, and grad mode is per thread. The exploration type is NOT set here: TorchRL keeps
    # it in a process-wide global, and two sessions entering and leaving set_exploration_type in
    # interleaved threads left it at DETERMINISTIC for the whole process (measured: ε-greedy stopped
    # exploring in later tests). The demo's policies need none: the greedy QValueActor is
    # deterministic and the random baseline is random in every mode.
    return env.step(policy(td))


def play(env, policy, question_id: str, question_text: str) -> Iterator[StepView]:
    """Yield a ``StepView`` after the reset and after every step, until the episode ends."""
    camera = env.base_env.camera if hasattr(env, "base_env") else env.camera
    with torch.no_grad():
        td = env.reset(question_id=question_id)
    first = td[keys.RGB].clone()
    first_answer = env.answer_image()
    tokens = td[keys.QUESTION].clone()
    yield StepView(0, annotate(_hwc(first), SCALE, [question_text, "step 0: first image"]), table_row(0, td, None))
    steps = []
    while True:
        td = _act_and_step(env, policy, td)
        step = len(steps)
        steps.append(td.select(*RECORDED, strict=False).clone())
        nxt = td["next"]
        view = StepView(step + 1, step_frame(td, nxt, camera, question_text, step),
                        table_row(step + 1, nxt, int(td[keys.ACTION])))
        if bool(nxt["done"].item()):
            view.done, view.rollout = True, torch.stack(steps, 0)
            view.first_rgb, view.last_rgb, view.tokens = _t(first), _t(nxt[keys.RGB]), tokens
            if first_answer is not None:
                view.answer_frames = (_t(first_answer), _t(env.answer_image()))
            yield view
            return
        yield view
        td = step_mdp(td)


def _t(rgb: torch.Tensor) -> torch.Tensor:
    return rgb.permute(1, 2, 0).contiguous()


def video_frames(rollout, camera, question_text: str) -> list[np.ndarray]:
    """The downloadable video's frames: the recipes' (Q maps beside them for a Q-network policy)."""
    if keys.ACTION_VALUE in rollout.keys():
        return qmap_episode_frames(rollout, camera, question_text, SCALE)
    return episode_frames(rollout, camera, question_text, SCALE)
