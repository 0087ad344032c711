"""The paper's reward formulas (Sec. IV-A3) as pure torch functions with any leading batch dims.

Objects live on the last dimension ([..., K]); ``mask`` / ``target_mask`` select the real objects
(the env pads to 50) or the question's targets. Degenerate cases give 0, never NaN or inf: no
target, or nothing left to reveal (a zero denominator). Slots a mask excludes never influence the
result, whatever they hold (NaN included); the selected slots must be finite, which the transforms
check (``mqa_rl.transforms.checks``) before calling these.
"""

from __future__ import annotations

import torch

EXPLORATION_CAP = 4.0     # the authors' code ignored displacement ratios ≥ 4 (teleport glitches)
NOTHING_TO_REVEAL = 1e-6  # overlap below this counts as 0 (a real χ is 0 or ≥ 1 / A_t ≈ 2e-5); keeps ratios finite


def exploration_reward(
    pos_before: torch.Tensor,
    pos_after: torch.Tensor,
    mask: torch.Tensor,
    scale: torch.Tensor | float,
    cap: float | None = EXPLORATION_CAP,
) -> torch.Tensor:
    """R_e = max_i |p_i − p_i'| / s_i over valid objects ([..., K, 3] → [...]).

    ``scale`` is s_i: a float (the push length, what the authors' code used) or a tensor [..., K]
    (e.g. |p_i|, the paper's printed formula). Ratios ≥ ``cap`` are non-physical jumps and ignored.
    """
    disp = (pos_after - pos_before).norm(dim=-1)
    scale = torch.as_tensor(scale, dtype=disp.dtype, device=disp.device)
    ratio = disp / scale.clamp(min=1e-9)
    keep = mask.bool() & torch.isfinite(ratio)
    if cap is not None:
        keep = keep & (ratio < cap)
    return torch.where(keep, ratio, torch.zeros_like(ratio)).amax(dim=-1) if ratio.shape[-1] else ratio.sum(-1)


def _relative_drop(before: torch.Tensor, after: torch.Tensor) -> torch.Tensor:
    """(before − after) / before, 0 where before is (numerically) 0."""
    some = before > NOTHING_TO_REVEAL
    safe = torch.where(some, before, torch.ones_like(before))
    return torch.where(some, (before - after) / safe, torch.zeros_like(before))


def global_occlusion_reward(chi_before: torch.Tensor, chi_after: torch.Tensor, target_mask: torch.Tensor) -> torch.Tensor:
    """R_g = (χ_a − χ_a') / χ_a with χ_a the mean overlap of the m targets ([..., K] → [...]).

    0 when m = 0 or χ_a = 0. R_g ≤ 1 (χ' ≥ 0); it is negative when the targets got more hidden.
    """
    t = target_mask.bool()
    m = t.sum(-1).to(chi_before.dtype)
    zero = torch.zeros_like(chi_before)
    mean_before = torch.where(t, chi_before, zero).sum(-1) / m.clamp(min=1)     # where, not ·mask: NaN · 0 is NaN
    mean_after = torch.where(t, chi_after, zero).sum(-1) / m.clamp(min=1)
    return torch.where(m > 0, _relative_drop(mean_before, mean_after), torch.zeros_like(m))


def local_occlusion_reward(
    chi_before: torch.Tensor, chi_after: torch.Tensor, target_mask: torch.Tensor, reduce: str = "max"
) -> torch.Tensor:
    """R_l = (max χ − max χ') / max χ over the targets: progress on the most hidden one ([..., K] → [...]).

    ``reduce="min"`` uses the least hidden target instead (the authors' code did so for EXISTENCE
    questions: one visible instance answers them). 0 when m = 0 or the denominator is 0.
    """
    if reduce not in ("max", "min"):
        raise ValueError(f"reduce must be 'max' or 'min', got {reduce!r}")
    t = target_mask.bool()
    if reduce == "max":
        fill = torch.full_like(chi_before, -1.0)
        before, after = torch.where(t, chi_before, fill).amax(-1), torch.where(t, chi_after, fill).amax(-1)
    else:
        fill = torch.full_like(chi_before, 2.0)
        before, after = torch.where(t, chi_before, fill).amin(-1), torch.where(t, chi_after, fill).amin(-1)
    any_target = t.any(-1)
    return torch.where(any_target, _relative_drop(before.clamp(0, 1), after.clamp(0, 1)), torch.zeros_like(before))


def beta_schedule(step: torch.Tensor | int, horizon: torch.Tensor | int, final: float = 0.5) -> torch.Tensor:
    """β = 1 − (1 − final) · S_n / T for S_n ≤ T, else ``final`` (S_n: DQN training steps, T: half the
    replay size). The paper's ``final`` is 0.5; 0 hands the reward entirely to R_q after T."""
    step = torch.as_tensor(step, dtype=torch.float32)
    horizon = torch.as_tensor(horizon, dtype=torch.float32)
    if (horizon <= 0).any():
        raise ValueError(f"the β horizon T must be positive, got {horizon}")
    if not 0.0 <= float(final) <= 1.0:
        raise ValueError(f"the final β must lie in [0, 1], got {final}")
    return 1.0 - (1.0 - float(final)) * (step.clamp(min=0) / horizon).clamp(max=1.0)


def is_simple_scene(chi: torch.Tensor, target_mask: torch.Tensor, threshold: float = 0.2) -> torch.Tensor:
    """The paper's "simple scene": every target is visible with χ ≤ threshold ([..., K] → [...] bool).

    A scene with no target is simple (nothing to reveal). Paper: 0.2; the authors' code: 0.1.
    """
    t = target_mask.bool()
    return (~t | (chi <= threshold)).all(-1)


def countable_targets_reward(visible_before: torch.Tensor, visible_after: torch.Tensor, target_mask: torch.Tensor,
                             min_px: float, per_target: bool = True) -> torch.Tensor:
    """R_c = (targets that rose to ≥ ``min_px`` visible pixels − targets that fell below) / number of targets
    ([..., K] → [...]; the raw count when not ``per_target``): what a perfect counter gains from the push, not
    how much of the targets shows. 0 without target."""
    targets = target_mask.bool()
    before, after = (visible_before >= min_px) & targets, (visible_after >= min_px) & targets
    net = ((after & ~before).sum(-1) - (before & ~after).sum(-1)).to(torch.float32)
    return net / targets.sum(-1).clamp(min=1) if per_target else net
