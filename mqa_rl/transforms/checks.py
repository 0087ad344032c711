"""Input and config checks shared by the reward transforms; every message names the transform.

The rule for measurements: slots that a mask excludes (padding, non-target objects, the push terms
of a stop) never influence a result, whatever they hold. A NaN or ±inf in a slot that counts raises
``ValueError`` naming the transform and the key: a reward computed from it would be NaN, or a 0 that
hides a broken measurement.
"""

from __future__ import annotations

import math
import numbers

import torch
from tensordict import TensorDictBase

MEASURED_BY_ENV = "SapienBinEnv writes it; a stored transition must keep both its root and \"next\""


def _name(owner) -> str:
    return type(owner).__name__


def _shown(key, where: str) -> str:
    """The key as it sits in a transition (under "next" for the state after the action), in double
    quotes: a ``KeyError`` prints its message with ``repr``, which would escape single ones."""
    parts = ((key,) if isinstance(key, str) else tuple(key)) if where == "root" else ("next", *((key,) if isinstance(key, str) else key))
    return f'"{parts[0]}"' if len(parts) == 1 else "(" + ", ".join(f'"{p}"' for p in parts) + ")"


def required(owner, td: TensorDictBase, key, where: str, hint: str = MEASURED_BY_ENV) -> torch.Tensor:
    """``td[key]``, or a ``KeyError`` that names the transform and the missing key.

    ``where`` is "root" (the state before the action) or "next" (the state after it).
    """
    value = td.get(key, None) if isinstance(td, TensorDictBase) else None
    if value is None:
        state = "before the action" if where == "root" else "after the action"
        raise KeyError(f"{_name(owner)} needs {_shown(key, where)} (the state {state}), which is missing; {hint}")
    return value


def next_state(owner, transition: TensorDictBase) -> TensorDictBase:
    """A stored transition's ``"next"`` (the state after the action), or a ``KeyError`` naming the transform."""
    nxt = transition.get("next", None)
    if nxt is None:
        raise KeyError(f"{_name(owner)} on a stored transition needs its \"next\" entry (the state after the action), "
                       f"which is missing; store whole transitions (a collector's or rollout's output)")
    return nxt


def finite_where(owner, value: torch.Tensor, counted: torch.Tensor | None, key, where: str) -> torch.Tensor:
    """``value`` unchanged when it is finite in every counted slot, else a ``ValueError``.

    ``counted`` is a mask over ``value``'s leading dims (e.g. [..., K] for positions [..., K, 3]);
    None counts every slot.
    """
    bad = ~torch.isfinite(value)
    if counted is not None:
        if bad.dim() > counted.dim():
            bad = bad.flatten(counted.dim()).any(-1)
        bad = bad & counted.bool()
    if bad.any():
        raise ValueError(f"{_name(owner)}: {_shown(key, where)} is NaN or infinite in {int(bad.sum())} slot(s) that "
                         f"count for the reward; check the measurements (slots the masks exclude may hold anything)")
    return value


def finite_number(owner, param: str, value, *, positive: bool = False, low: float | None = None,
                  high: float | None = None) -> float:
    """A config value as a float: a real finite number (not a bool), optionally > 0 or within [low, high]."""
    ok = not isinstance(value, bool) and isinstance(value, numbers.Real) and math.isfinite(value)
    ok = ok and not (positive and value <= 0) and not (low is not None and value < low) \
        and not (high is not None and value > high)
    if not ok:
        bounds = " > 0" if positive else f" in [{low}, {high}]" if low is not None else ""
        raise ValueError(f"{_name(owner)}: {param} must be a finite number{bounds}, got {value!r}")
    return float(value)
