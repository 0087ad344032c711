"""How well an MQA system answers, from its test rollouts (``mqa_rl.collectors.rollouts``) and its VQA.

* ``predict``: the VQA's answers to the stored episodes (through the public ``answer_probs``).
* ``accuracy_table``: accuracy per (question type, level) with Wilson 95 % intervals: with ~200
  questions per level and accuracies near 0.3-0.6, a normal interval would be fine too, but Wilson
  stays inside [0, 1] for the small groups of tiny runs.
* ``paired_difference``: system A − system B on the questions both answered (the test plan is the same
  for every system, so the difference is paired by question, much tighter than two separate intervals).
* ``accuracy_by_scene`` / ``paired_difference_by_scene``: the same with intervals that resample whole
  scenes, as a result on 9-12 test piles per level, or on a held-out set of fresh piles, needs.
* ``counter_right``: whether a *perfect counter* (counts the targets with ≥ ``min_px`` visible pixels)
  would answer a COUNTING question right from the episode's first or last image: what the images
  allow, whatever the VQA makes of them. ``frame=EITHER``: the targets
  countable in either image (objects do not vanish between the frames, so what one frame shows is
  evidence the pair holds: the ceiling of a VQA that reads both, ``frame_fusion="max"``).
* ``calibrated_counter_right``: the same perfect count, mapped to the answer most often seen with that
  count at that level in the system's *training* rollouts: the best a VQA that reads only the visible
  count can do. In hard scenes the answer counts hidden objects too, so a visible count of 2 is more
  often a 3; this, not the raw counter, is the ceiling to hold a count-reading VQA against.
* ``prior_answers``: the majority answer per (type, level) among the training questions: a VQA that
  ignores the images and the question's object can reach this.
* ``policy_stats``: pushes, targets' χ at the end and its change, targets made countable − buried, per level, ± 95 % (``mean_ci95``).
"""

from __future__ import annotations

import math
from collections import Counter

import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.data.dataset import LEVELS
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.evaluation.episode_metrics import mean_ci95, scene_bootstrap_ci95
from mqa_rl.transforms.episode_stats import COUNTABLE_PX

EITHER = "either"          # countable_targets' frame: a target countable in I_start or in I_stop


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float, float]:
    """(proportion, low, high) of the Wilson score interval; NaNs when n = 0."""
    if n == 0:
        return math.nan, math.nan, math.nan
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return p, max(0.0, centre - half), min(1.0, centre + half)


@torch.no_grad()
def predict(model, records: TensorDict, batch_size: int = 64) -> torch.Tensor:
    """Answer indices [N] the VQA gives to the records (question tokens, ``FIRST_RGB``, ``LAST_RGB``)."""
    out = []
    for start in range(0, records.shape[0], batch_size):
        batch = records[start:start + batch_size]
        first = batch.get(keys.FIRST_RGB).permute(0, 2, 3, 1)
        last = batch.get(keys.LAST_RGB).permute(0, 2, 3, 1)
        out.append(model.answer_probs(batch.get(keys.QUESTION), first, last).argmax(-1))
    return torch.cat(out) if out else torch.zeros(0, dtype=torch.int64)


def groups(records: TensorDict):
    """(type name, level name, bool mask [N]) for every group present, then (type, "all", mask) per type."""
    types, levels = records.get(keys.TYPE_LABEL), records.get(keys.LEVEL)
    for t, qtype in enumerate(QUESTION_TYPES):
        if not (types == t).any():
            continue
        for lv, level in enumerate(LEVELS):
            mask = (types == t) & (levels == lv)
            if mask.any():
                yield qtype, level, mask
        yield qtype, "all", types == t


def accuracy_table(right: torch.Tensor, records: TensorDict) -> dict[str, dict[str, dict]]:
    """{type: {level or "all": {"accuracy", "low", "high", "n"}}} of a bool [N] per record."""
    table: dict[str, dict[str, dict]] = {}
    for qtype, level, mask in groups(records):
        k, n = int(right[mask].sum()), int(mask.sum())
        p, lo, hi = wilson(k, n)
        table.setdefault(qtype, {})[level] = {"accuracy": p, "low": lo, "high": hi, "n": n}
    return table


def _per_question(right: torch.Tensor, question: torch.Tensor) -> dict[int, float]:
    sums: dict[int, list[float]] = {}
    for r, q in zip(right.float().tolist(), question.tolist()):
        sums.setdefault(q, []).append(r)
    return {q: sum(v) / len(v) for q, v in sums.items()}


def paired_difference(right_a: torch.Tensor, records_a: TensorDict, right_b: torch.Tensor, records_b: TensorDict,
                      mask_a: torch.Tensor | None = None) -> tuple[float, float, int]:
    """(mean of A − B, 95 % half-width, n) over the questions both answered (rollouts of a question averaged),
    restricted to A's records in ``mask_a``."""
    mask_a = torch.ones_like(right_a, dtype=torch.bool) if mask_a is None else mask_a
    a = _per_question(right_a[mask_a], records_a.get(keys.QUESTION_ID)[mask_a])
    b = _per_question(right_b, records_b.get(keys.QUESTION_ID))
    common = sorted(set(a) & set(b))
    return mean_ci95(torch.tensor([a[q] - b[q] for q in common], dtype=torch.float64))


def paired_difference_by_scene(right_a: torch.Tensor, records_a: TensorDict, right_b: torch.Tensor,
                               records_b: TensorDict, mask_a: torch.Tensor | None = None) -> tuple[float, float, float, int]:
    """(mean of A − B, low, high, scenes): ``paired_difference`` with a 95 % interval that resamples whole
    scenes (``scene_bootstrap_ci95``): one pile's questions share its occlusions, so they are not independent."""
    mask_a = torch.ones_like(right_a, dtype=torch.bool) if mask_a is None else mask_a
    a = _per_question(right_a[mask_a], records_a.get(keys.QUESTION_ID)[mask_a])
    b = _per_question(right_b, records_b.get(keys.QUESTION_ID))
    scene = dict(zip(records_a.get(keys.QUESTION_ID).tolist(), records_a.get(keys.SCENE).tolist()))
    common = sorted(set(a) & set(b))
    return scene_bootstrap_ci95(torch.tensor([a[q] - b[q] for q in common], dtype=torch.float64),
                                torch.tensor([scene[q] for q in common], dtype=torch.int64))


def accuracy_by_scene(right: torch.Tensor, records: TensorDict) -> dict[str, tuple[float, float, float, int]]:
    """{level: (accuracy, low, high, scenes)} of COUNTING records with scene-resampled 95 % intervals."""
    counting = records.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting")
    out = {}
    for i, level in enumerate(LEVELS):
        m = counting & (records.get(keys.LEVEL) == i)
        if m.any():
            out[level] = scene_bootstrap_ci95(right[m].double(), records.get(keys.SCENE)[m])
    return out


def countable_targets(records: TensorDict, frame: str = keys.LAST, min_px: float = COUNTABLE_PX) -> torch.Tensor:
    """Int [N]: the question's targets with ≥ ``min_px`` visible pixels in ``frame`` (what a perfect counter reads);
    ``frame=EITHER``: in I_start or I_stop (the same object counted once)."""
    frames = (keys.FIRST, keys.LAST) if frame == EITHER else (frame,)
    countable = torch.stack([records.get((f, keys.FRAME_VISIBLE)) >= min_px for f in frames]).any(0)
    return (countable & records.get(keys.EPISODE_TARGETS)).sum(-1)


def counter_right(records: TensorDict, answers, frame: str = keys.LAST, min_px: float = COUNTABLE_PX) -> torch.Tensor:
    """Bool [N]: a perfect counter of the targets with ≥ ``min_px`` visible pixels in ``frame`` is right
    (COUNTING records only; False elsewhere)."""
    counted = countable_targets(records, frame, min_px)
    labels = records.get(keys.ANSWER_LABEL).tolist()
    truth = torch.tensor([int(answers[a]) if answers[a].isdigit() else -1 for a in labels])
    return (counted == truth) & (records.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting"))


def calibrated_counter_right(train: TensorDict, test: TensorDict, frame: str = keys.LAST,
                             min_px: float = COUNTABLE_PX) -> torch.Tensor:
    """Bool [N test]: the answer most frequent in ``train`` for the same (level, perfect visible count) is
    right (the level's most frequent answer for a count never seen in training); COUNTING records only,
    False elsewhere. Both record sets need the keys ``countable_targets`` reads, the level and the answer."""
    counting = QUESTION_TYPES.index("counting")
    seen: dict[tuple[int, int], Counter] = {}
    by_level: dict[int, Counter] = {}
    rows = zip(train.get(keys.LEVEL).tolist(), countable_targets(train, frame, min_px).tolist(),
               train.get(keys.ANSWER_LABEL).tolist(), train.get(keys.TYPE_LABEL).tolist())
    for level, count, answer, qtype in rows:
        if qtype == counting:
            seen.setdefault((level, count), Counter())[answer] += 1
            by_level.setdefault(level, Counter())[answer] += 1
    guesses = []
    for level, count in zip(test.get(keys.LEVEL).tolist(), countable_targets(test, frame, min_px).tolist()):
        table = seen.get((level, count)) or by_level.get(level)
        guesses.append(table.most_common(1)[0][0] if table else -1)
    truth = test.get(keys.ANSWER_LABEL)
    return (torch.tensor(guesses, dtype=truth.dtype) == truth) & (test.get(keys.TYPE_LABEL) == counting)


def prior_answers(dataset, split: str = "train") -> dict[tuple[int, int], int]:
    """{(type index, level index): answer index} the most frequent answer among ``split``'s questions."""
    counts: dict[tuple[int, int], Counter] = {}
    answer_index = {a: i for i, a in enumerate(dataset.answers)}
    for q in dataset.select(split=split):
        key = (QUESTION_TYPES.index(q.type), LEVELS.index(dataset.scene(q.scene_id).difficulty))
        counts.setdefault(key, Counter())[answer_index[q.answer]] += 1
    return {k: c.most_common(1)[0][0] for k, c in counts.items()}


def prior_right(records: TensorDict, prior: dict[tuple[int, int], int]) -> torch.Tensor:
    """Bool [N]: the training prior's answer is right."""
    guess = torch.tensor([prior.get((t, lv), -1) for t, lv in zip(records.get(keys.TYPE_LABEL).tolist(),
                                                                   records.get(keys.LEVEL).tolist())])
    return guess == records.get(keys.ANSWER_LABEL)


def policy_stats(records: TensorDict) -> dict[str, dict[str, tuple[float, float, int]]]:
    """{level or "all": {"pushes" | "chi_end" | "chi_change" | "stopped" | "countable_gain": (mean, 95 % half-width,
    n)}}; ``countable_gain``: targets made countable (≥ ``COUNTABLE_PX`` visible pixels) between I_start and I_stop
    minus targets pushed below that line, per episode."""
    levels = records.get(keys.LEVEL)
    chi_start, chi_end = records.get(keys.CHI_START), records.get(keys.CHI_END)
    targets = records.get(keys.EPISODE_TARGETS)
    start, end = ((records.get((f, keys.FRAME_VISIBLE)) >= COUNTABLE_PX) & targets for f in (keys.FIRST, keys.LAST))
    values = {"pushes": records.get(keys.PUSHES).float(), "chi_end": chi_end, "chi_change": chi_end - chi_start,
              "stopped": records.get(keys.STOPPED).float(),
              "countable_gain": ((end & ~start).sum(-1) - (start & ~end).sum(-1)).float()}
    out = {}
    for name, mask in [*((lv, levels == i) for i, lv in enumerate(LEVELS)), ("all", torch.ones_like(levels, dtype=torch.bool))]:
        if mask.any():
            out[name] = {k: mean_ci95(v[mask]) for k, v in values.items()}
    return out
