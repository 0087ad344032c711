"""Fit a ``StopCritic`` to a frozen push policy's own episodes: optimal stopping by regression
(Longstaff & Schwartz 2001, with one regressor shared over the steps).

Each episode is the policy pushing without stopping: features f_t of the states s_0 … s_{T-1} where it
could stop, and the targets' mean χ_0 … χ_T (χ_T: after the last push, where the episode ends anyway).
Stopping at t yields χ_t; pushing on yields the value V_{t+1} of the states after it, where
V_T = χ_T and V_t = χ_t if the current rule stops at t, else V_{t+1}, the realised χ of the path, not a
prediction (what keeps the method from compounding the regressor's errors). The critic regresses the
gain of pushing on, V_{t+1} − χ_t, on f_t; the rule "stop when the predicted gain >= 0" then changes
the V_t of earlier steps, so fitting repeats a few times, starting from "never stop".
"""

from __future__ import annotations

import torch

from mqa_rl.modules.stop.learned_stop import StopCritic


def realised_values(chi: torch.Tensor, stop: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """V [E, T + 1] of the rule ``stop`` [E, T] (bool) on paths ``chi`` [E, T + 1]; a step that is not
    ``valid`` (after an episode ended early; chi holds its last value there) counts as a stop."""
    values = chi.clone()
    for t in range(chi.shape[1] - 2, -1, -1):
        values[:, t] = torch.where(stop[:, t] | ~valid[:, t], chi[:, t], values[:, t + 1])
    return values


def stopped_chi(chi: torch.Tensor, stop: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """[E] the χ each episode ends with under the rule ``stop``: V_0."""
    return realised_values(chi, stop, valid)[:, 0]


def fit_stop_critic(features: torch.Tensor, chi: torch.Tensor, valid: torch.Tensor, *, hidden: int = 32,
                    iterations: int = 3, steps: int = 1500, lr: float = 3e-3, weight_decay: float = 1e-3,
                    seed: int = 0) -> tuple[StopCritic, list[dict]]:
    """A critic from episodes: ``features`` [E, T, F], ``chi`` [E, T + 1], ``valid`` [E, T] bool.

    Returns (critic, history): per iteration the regression's mean squared error and the mean χ its rule
    ends with on these episodes."""
    if features.shape[:2] != valid.shape or chi.shape != (valid.shape[0], valid.shape[1] + 1):
        raise ValueError(f"shapes: features {tuple(features.shape)}, chi {tuple(chi.shape)}, valid {tuple(valid.shape)}; "
                         "expected [E, T, F], [E, T + 1], [E, T]")
    if not bool(torch.isfinite(chi).all() and torch.isfinite(features).all()):
        raise ValueError("non-finite χ or features: leave out episodes without targets before fitting")
    generator = torch.Generator().manual_seed(int(seed))
    torch.manual_seed(int(seed))
    critic = StopCritic(features.shape[-1], hidden)
    critic.standardise_by(features[valid])
    rows = features[valid]
    stop = torch.zeros_like(valid)                       # start from "never stop"
    history = []
    for iteration in range(int(iterations)):
        values = realised_values(chi, stop, valid)
        target = (values[:, 1:] - chi[:, :-1])[valid]
        optimiser = torch.optim.Adam(critic.parameters(), lr=lr, weight_decay=weight_decay)
        for _ in range(int(steps)):
            batch = torch.randint(0, rows.shape[0], (min(512, rows.shape[0]),), generator=generator)
            loss = torch.nn.functional.mse_loss(critic(rows[batch]), target[batch])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
        with torch.no_grad():
            mse = float(torch.nn.functional.mse_loss(critic(rows), target))
            stop = (critic(features) >= 0) & valid
        history.append({"iteration": iteration, "mse": mse, "target_var": float(target.var()),
                        "stop_rate": float(stop[valid].float().mean()),
                        "chi_end": float(stopped_chi(chi, stop, valid).mean())})
    return critic.eval(), history


def fixed_rules(chi: torch.Tensor, valid: torch.Tensor) -> dict[str, float]:
    """Mean final χ of the simple rules on the same episodes: stop at once, after k pushes, never, and
    the hindsight best stop (min over the path: no rule can beat it)."""
    out = {}
    for k in range(chi.shape[1]):
        stop = torch.zeros_like(valid)
        if k < valid.shape[1]:
            stop[:, k] = True
        out[f"after_{k}"] = float(stopped_chi(chi, stop, valid).mean())
    out["hindsight"] = float(chi.min(1).values.mean())
    return out
