"""``generate_dataset``'s arguments, checked before any work: a bad one costs no settling time.

Scene counts are non-negative whole numbers (not bools, not floats) of known difficulty levels and
plan at least one scene: a dataset without scenes is useless, so it is refused rather than written.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping


def whole_number(value, what: str, minimum: int) -> int:
    """``value`` as an int ≥ ``minimum``; bools, floats and strings are refused, naming ``what``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{what} must be a whole number ≥ {minimum}, got {value!r} ({type(value).__name__})")
    if value < minimum:
        raise ValueError(f"{what} must be ≥ {minimum}, got {value}")
    return int(value)


def level_counts(counts, levels, what: str, minimum: int) -> dict[str, int]:
    """A mapping difficulty level → whole number ≥ ``minimum``, each level one of ``levels``."""
    if not isinstance(counts, Mapping):
        raise ValueError(f"{what} must map difficulty levels {list(levels)} to counts, got {counts!r}")
    unknown = set(counts) - set(levels)
    if unknown:
        raise ValueError(f"unknown difficulty {sorted(unknown, key=str)} in {what}; allowed: {list(levels)}")
    return {level: whole_number(n, f"{what}[{level!r}]", minimum) for level, n in counts.items()}


def scene_plan(num_scenes, objects_per_scene, levels: Mapping[str, int]) -> tuple[dict[str, int], dict[str, int]]:
    """Checked ``(num_scenes, objects per level)``; refuses a plan with no scene at all."""
    counts = level_counts(num_scenes, levels, "num_scenes", 0)
    if sum(counts.values()) == 0:
        raise ValueError(f"num_scenes={dict(num_scenes)!r} plans no scene: a dataset needs at least one, "
                         f"e.g. num_scenes={{'easy': 1}}")
    per_level = {**levels, **level_counts(objects_per_scene or {}, levels, "objects_per_scene", 1)}
    return counts, per_level


def seed_and_fraction(seed, train_fraction) -> tuple[int, float]:
    """A non-negative integer seed and a train fraction strictly between 0 and 1."""
    seed = whole_number(seed, "seed", 0)
    if isinstance(train_fraction, bool) or not isinstance(train_fraction, numbers.Real) or not 0 < train_fraction < 1:
        raise ValueError(f"train_fraction must be a number in (0, 1), got {train_fraction!r}")
    return seed, float(train_fraction)
