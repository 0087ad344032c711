"""What an episode achieved, read from the tensordict of its last step (``data["next"][done]``).

Needs ``EpisodeStats`` in the env (``make_mqa_env(..., episode_stats=True)``). Per episode:

* ``reward`` and ``term/<name>``: sums over the episode
* ``pushes``: pushes executed; ``stopped``: ended by stop (else by the push limit)
* ``final_simple``: the last image is a simple scene (every target visible with χ ≤ threshold)
* ``chi_start`` / ``chi_end``: mean χ of the targets in the first / last image; ``chi_change`` =
  end − start (negative: targets got uncovered)
* ``hidden_end``: fraction of the targets fully hidden (χ = 1) in the last image
* ``into_view`` / ``out_of_view``: fraction of the targets that crossed the counting line (``COUNTABLE_PX``
  visible pixels) between the first and last image, upwards / downwards; ``in_view_change`` their
  difference. This is what an answer can gain: χ falls also on targets a counter already sees.
* ``countable_made`` / ``countable_buried``: the same crossings as counts of targets; ``countable_gain`` =
  made − buried, per episode (0 without target): the net number of targets a perfect counter gains.
* ``counter_start`` / ``counter_stop`` / ``counter_either``: 1 when a perfect counter (targets with ≥
  ``COUNTABLE_PX`` visible pixels) reads the COUNTING answer (every target of the class) from I_start / I_stop /
  the two frames together (a target countable in either, counted once); NaN for the other question types.

The χ and view-fraction metrics are NaN for episodes whose question has no target in the bin (a COUNTING
answer 0); ``summarise`` ignores NaN.
"""

from __future__ import annotations

import math

import torch
from tensordict import TensorDictBase

from mqa_rl import keys
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.transforms.episode_stats import mean_target_chi, targets_in_view
from mqa_rl.transforms.functional import is_simple_scene

FULLY_HIDDEN = 1.0 - 1e-6
FINAL_KEYS = (keys.TARGET_MASK, keys.OVERLAP, keys.VISIBLE_AREA, keys.TARGET_CHI_START, keys.TARGETS_IN_VIEW_START,
              keys.EPISODE_REWARD, keys.PUSH_COUNT, keys.IS_STOP, keys.EPISODE_TERMS, keys.QUESTION_TYPE)
COUNTING = QUESTION_TYPES.index("counting")


def episode_metrics(final: TensorDictBase, simple_threshold: float = 0.2) -> dict[str, torch.Tensor]:
    """Metrics [E] from the last-step tensordicts [E] of E finished episodes."""
    tmask = final.get(keys.TARGET_MASK)
    has_target = tmask.any(-1)
    nan = torch.full(has_target.shape, math.nan)
    chi_start = final.get(keys.TARGET_CHI_START).squeeze(-1)
    chi_end = mean_target_chi(final).squeeze(-1)
    hidden = _hidden_fraction(final)
    out = {
        "reward": final.get(keys.EPISODE_REWARD).squeeze(-1),
        "pushes": final.get(keys.PUSH_COUNT).squeeze(-1).to(torch.float32),
        "stopped": final.get(keys.IS_STOP).squeeze(-1).to(torch.float32),
        "final_simple": is_simple_scene(final.get(keys.OVERLAP), tmask, simple_threshold).to(torch.float32),
        "chi_start": torch.where(has_target, chi_start, nan),
        "chi_end": torch.where(has_target, chi_end, nan),
        "chi_change": torch.where(has_target, chi_end - chi_start, nan),
        "hidden_end": torch.where(has_target, hidden, nan),
    }
    start, end, n = final.get(keys.TARGETS_IN_VIEW_START), targets_in_view(final), tmask.sum(-1).clamp(min=1)
    into, out_of = (end & ~start).sum(-1) / n, (start & ~end).sum(-1) / n
    out["into_view"] = torch.where(has_target, into.to(torch.float32), nan)
    out["out_of_view"] = torch.where(has_target, out_of.to(torch.float32), nan)
    out["in_view_change"] = torch.where(has_target, (into - out_of).to(torch.float32), nan)
    made, buried = _crossings(start, end)
    out.update(countable_made=made, countable_buried=buried, countable_gain=made - buried)
    qtype = final.get(keys.QUESTION_TYPE, None)
    counting = (qtype.squeeze(-1) == COUNTING) if qtype is not None else torch.zeros_like(has_target)
    targets = tmask.sum(-1)
    for name, seen in (("counter_start", start), ("counter_stop", end), ("counter_either", start | end)):
        out[name] = _counter_right(seen, targets, counting)
    terms = final.get(keys.EPISODE_TERMS, None)
    if terms is not None:
        for name in terms.keys():
            out[f"term/{name}"] = terms.get(name).squeeze(-1)
    return out


def _counter_right(seen: torch.Tensor, targets: torch.Tensor, counting: torch.Tensor) -> torch.Tensor:
    """1 where the targets a perfect counter sees are all the targets of a COUNTING question, NaN for other types."""
    right = (seen.sum(-1) == targets).to(torch.float32)
    return torch.where(counting, right, torch.full_like(right, math.nan))


def kept_frame_metrics(start: TensorDictBase, state: TensorDictBase) -> dict[str, torch.Tensor]:
    """[E] each: what ``state``'s frame (e.g. a kept frame, the I_stop of a system that answers from it) holds against
    ``start``'s (I_start): ``counter_kept`` (the perfect counter reads the COUNTING answer from it; NaN for the other
    question types), ``countable_gain_kept`` (targets countable in it and not at the start, minus the reverse),
    ``chi_kept`` and ``hidden_kept`` (the targets' mean χ and fraction fully hidden in it; NaN without target)."""
    tmask = state.get(keys.TARGET_MASK)
    counting = state.get(keys.QUESTION_TYPE).reshape(tmask.shape[:-1]) == COUNTING
    after = targets_in_view(state)
    made, buried = _crossings(targets_in_view(start), after)
    has_target = tmask.any(-1)
    nan = torch.full(has_target.shape, math.nan)
    return {"counter_kept": _counter_right(after, tmask.sum(-1), counting),
            "countable_gain_kept": made - buried,
            "chi_kept": torch.where(has_target, mean_target_chi(state).squeeze(-1), nan),
            "hidden_kept": torch.where(has_target, _hidden_fraction(state), nan)}


def _crossings(before: torch.Tensor, after: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """[E] each: targets countable in ``after`` and not in ``before`` (made countable), and the reverse (buried)."""
    return (after & ~before).sum(-1).to(torch.float32), (before & ~after).sum(-1).to(torch.float32)


def _hidden_fraction(td: TensorDictBase) -> torch.Tensor:
    """[E] the fraction of the question's targets fully hidden (χ = 1) in ``td``'s frame (0 without target)."""
    tmask = td.get(keys.TARGET_MASK)
    return (((td.get(keys.OVERLAP) >= FULLY_HIDDEN) & tmask).sum(-1) / tmask.sum(-1).clamp(min=1)).to(torch.float32)


IDLE_MOVE_M = 0.005          # a push that moves no object by this much (5 mm) moved nothing


def idle_pushes(rollout: TensorDictBase, min_move: float = IDLE_MOVE_M) -> torch.Tensor:
    """[] pushes of one episode's rollout [T] that moved no object by ``min_move`` metres (wasted: the scene, and
    so the answer, is what it was); the stop is not a push."""
    before, after = rollout.get(keys.OBJECT_POS), rollout.get(("next", *keys.OBJECT_POS))
    moved = (after - before).norm(dim=-1).amax(-1)                         # [T] the largest object displacement
    pushed = ~rollout.get(("next", *keys.IS_STOP)).reshape(-1)
    return ((moved < min_move) & pushed).sum().to(torch.float32)


def mean_ci95(values: torch.Tensor) -> tuple[float, float, int]:
    """(mean, half-width of the 95 % interval, n) over the finite values; normal approximation
    (1.96 · sample std / √n), which suits the ≥ 100 episodes of an evaluation. NaN when n < 2."""
    v = values[torch.isfinite(values)].to(torch.float64)
    n = v.numel()
    if n == 0:
        return math.nan, math.nan, 0
    if n == 1:
        return float(v[0]), math.nan, 1
    return float(v.mean()), float(1.96 * v.std(unbiased=True) / math.sqrt(n)), n


def summarise(metrics: dict[str, torch.Tensor]) -> dict[str, float]:
    """Means of every metric (NaN-aware), for the logs."""
    return {k: mean_ci95(v)[0] for k, v in metrics.items()}


def scene_bootstrap_ci95(values: torch.Tensor, scenes: torch.Tensor, *, draws: int = 2000, seed: int = 0) -> tuple[float, float, float, int]:
    """(mean, low, high, scenes) of ``values`` with a 95 % interval that resamples whole scenes (a cluster
    bootstrap): the questions of one pile share its occlusions, so they are not independent, and with
    9-12 test scenes per level an interval over questions would be far too narrow."""
    v = values.to(torch.float64)
    ids, inverse = torch.unique(scenes, return_inverse=True)
    n = len(ids)
    if n == 0:
        return math.nan, math.nan, math.nan, 0
    sums = torch.zeros(n, dtype=torch.float64).index_add_(0, inverse, v)
    counts = torch.zeros(n, dtype=torch.float64).index_add_(0, inverse, torch.ones_like(v))
    g = torch.Generator().manual_seed(seed)
    pick = torch.randint(n, (draws, n), generator=g)
    means = sums[pick].sum(1) / counts[pick].sum(1)
    low, high = torch.quantile(means, torch.tensor([0.025, 0.975], dtype=torch.float64)).tolist()
    return float(v.mean()), low, high, n
