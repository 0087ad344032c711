"""The paper's four question templates with oracle answers computed from a stored scene.

SPATIAL "under": object A is under object B when B's centre is higher than A's centre and their
full silhouettes seen from the top camera (as if nothing else were there) overlap by at least
``UNDER_MIN_OVERLAP`` of the smaller silhouette. "Is there a {OBJ1} under the {OBJ2}?" is "yes"
when some instance of OBJ1 is under some instance of OBJ2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

QUESTION_TYPES = ("counting", "existence", "spatial", "logic")
UNDER_MIN_OVERLAP = 0.05      # fraction of the smaller silhouette
UNDER_MIN_PIXELS = 4


@dataclass(frozen=True, slots=True)
class Question:
    id: str
    scene_id: str
    type: str                   # one of QUESTION_TYPES
    text: str
    tokens: tuple[int, ...]
    classes: tuple[str, ...]    # class names asked about, in template order
    answer: str                 # one of vocab.ANSWERS


def question_text(qtype: str, classes: tuple[str, ...], phrases: dict[str, tuple[str, str]]) -> str:
    """Template text with natural singular ("an apple") and plural ("apples") phrases."""
    one = lambda c: phrases[c][0]                                   # noqa: E731
    the = lambda c: "the " + phrases[c][0].split(" ", 1)[1]          # noqa: E731  ("a can" → "the can")
    if qtype == "counting":
        return f"How many {phrases[classes[0]][1]} are there in the bin?"
    if qtype == "existence":
        return f"Is there {one(classes[0])} in the bin?"
    if qtype == "spatial":
        return f"Is there {one(classes[0])} under {the(classes[1])}?"
    if qtype == "logic":
        return f"Is there {one(classes[0])} and {one(classes[1])} in the bin?"
    raise ValueError(f"unknown question type {qtype!r}; allowed: {QUESTION_TYPES}")


def under_matrix(silhouettes: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """[N, N] bool, entry (a, b) = object a is under object b (see module docstring)."""
    flat = silhouettes.reshape(len(silhouettes), -1).astype(np.float32)
    inter = flat @ flat.T
    area = flat.sum(1)
    smaller = np.minimum(area[:, None], area[None, :])
    overlap = (inter >= UNDER_MIN_PIXELS) & (inter >= UNDER_MIN_OVERLAP * np.maximum(smaller, 1))
    lower = heights[:, None] < heights[None, :]
    return overlap & lower


def scene_questions(
    scene_id: str,
    object_classes: list[str],
    under: np.ndarray,
    classes: tuple[str, ...],
    phrases: dict[str, tuple[str, str]],
) -> list[tuple[str, str, tuple[str, ...], str]]:
    """All questions of one scene as (id, type, classes, answer): per class one COUNTING and one
    EXISTENCE, per ordered pair of distinct classes one SPATIAL and one LOGIC (20 classes → 800)."""
    counts = {c: 0 for c in classes}
    for c in object_classes:
        counts[c] += 1
    members = {c: [i for i, oc in enumerate(object_classes) if oc == c] for c in classes}
    yes_no = lambda b: "yes" if b else "no"                          # noqa: E731
    out = []
    for c in classes:
        out.append((f"{scene_id}/counting/{c}", "counting", (c,), str(counts[c])))
    for c in classes:
        out.append((f"{scene_id}/existence/{c}", "existence", (c,), yes_no(counts[c] > 0)))
    for c1 in classes:
        for c2 in classes:
            if c1 != c2:
                hit = bool(members[c1] and members[c2] and under[np.ix_(members[c1], members[c2])].any())
                out.append((f"{scene_id}/spatial/{c1}/{c2}", "spatial", (c1, c2), yes_no(hit)))
    for c1 in classes:
        for c2 in classes:
            if c1 != c2:
                out.append((f"{scene_id}/logic/{c1}/{c2}", "logic", (c1, c2), yes_no(counts[c1] > 0 and counts[c2] > 0)))
    return out
