"""Supervised losses on demonstrations beside TorchRL's ``DQNLoss``: which action the demonstrator took.

``margin`` is DQfD's large-margin loss (Hester et al. 2018),

    J_E = max_a [Q(s, a) + l(a_E, a)] − Q(s, a_E),   l = ``margin`` for a ≠ a_E, 0 for a = a_E,

over the actions the state's mask allows: the demonstrated action must out-value every other one by
the margin. Its gradient reaches two actions per state (the demonstrated one and the current max),
and on a flat Q map over ~3,500 allowed pushes the max moves every step: measured here, it stayed at
its plateau (loss = margin) for 1,200 updates. ``push_cross_entropy`` is the cross-entropy of the
softmax of Q over the allowed pushes against the demonstrated push (stops are left to the TD loss:
with stops in the softmax, the single stop action becomes the mode and the greedy policy always
stops): a gradient on every action (docs/notebook/policy.md: the margin, then the cross-entropy). ``stop_margin`` > 0 adds DQfD's
large margin to the one decision the cross-entropy leaves out, stop or push: in a demonstrated stop
Q(stop) must beat the best allowed push by the margin, in a demonstrated push the best push must beat
Q(stop) by it. ``direction_weight`` > 0 adds the cross-entropy of the 8 directions' Q at the
demonstrated push's start cell against its direction: the softmax over all pushes is dominated by
*where* (thousands of cells), and measured on the image teacher's demonstrations the head then learnt
where but not which way (direction at the teacher's cell at chance, 1/8); this term asks "which way,
given where" on its own (with the rotated head: 0.35 held-out; docs/notebook/policy.md, the direction term).
Demonstrated actions that the mask forbids (rare: an oracle push starting over a wall) are left out.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from torchrl.objectives import LossModule

from mqa_rl import keys
from mqa_rl.envs import actions


KINDS = ("margin", "push_cross_entropy")


class DemonstrationLoss(LossModule):
    """Writes ``loss_demo`` (weighted) and for the logs ``demo_agreement`` (the greedy action is the
    demonstrated one; with the cross-entropy, the greedy push) and ``demo_near`` (same direction, start
    within 2 grid cells; or both stop) and ``demo_stop_agreement`` (greedy stops where the demonstrator
    stopped and pushes where it pushed)."""

    def __init__(self, net: torch.nn.Module, kind: str = "margin", margin: float = 0.5, weight: float = 1.0,
                 smooth_cells: float = 0.0, stop_margin: float = 0.0, direction_weight: float = 0.0):
        super().__init__()
        if kind not in KINDS:
            raise ValueError(f"unknown demonstration loss {kind!r}; choose one of {KINDS}")
        if not (margin > 0 and weight > 0):
            raise ValueError(f"the demonstration margin and weight must be > 0, got {margin} and {weight}")
        if smooth_cells < 0 or stop_margin < 0 or direction_weight < 0:
            raise ValueError(f"smooth_cells, stop_margin and direction_weight must be ≥ 0, got {smooth_cells}, "
                             f"{stop_margin} and {direction_weight}")
        self.net, self.kind, self.margin, self.weight = net, kind, float(margin), float(weight)
        self.smooth_cells, self.stop_margin = float(smooth_cells), float(stop_margin)
        self.direction_weight = float(direction_weight)

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        q = self.net(tensordict.get(keys.RGB), tensordict.get(keys.DEPTH), tensordict.get(keys.QUESTION))
        mask = tensordict.get(keys.ACTION_MASK)
        demo = tensordict.get(keys.ACTION).reshape(-1)
        ok = mask.gather(-1, demo[:, None]).squeeze(-1)
        pushes = mask.clone()                   # the allowed pushes: mask without stop
        pushes[:, actions.STOP] = False
        stop_loss, stop_agree = self._stop_decision(q, pushes, demo, ok)
        if self.kind == "push_cross_entropy":
            ok = ok & (demo != actions.STOP)
        if not ok.any():
            zero = q.sum() * 0.0
            return TensorDict({"loss_demo": self.weight * stop_loss + zero, "demo_agreement": zero.detach(),
                               "demo_near": zero.detach(), "demo_stop_agreement": stop_agree}, [])
        q, mask, pushes, demo = q[ok], mask[ok], pushes[ok], demo[ok]
        if self.kind == "margin":
            bonus = torch.full_like(q, self.margin).scatter(-1, demo[:, None], 0.0)
            best = (q + bonus).masked_fill(~mask, torch.finfo(q.dtype).min).max(-1).values
            loss = (best - q.gather(-1, demo[:, None]).squeeze(-1)).mean()
        else:
            masked = q.masked_fill(~pushes, torch.finfo(q.dtype).min)
            if self.smooth_cells > 0:
                target = smoothed_push_target(demo, pushes, self.smooth_cells)
                logp = torch.where(target > 0, F.log_softmax(masked, -1), 0.0)
                loss = -(target * logp).sum(-1).mean()
            else:
                loss = F.cross_entropy(masked, demo)
        if self.direction_weight > 0:
            loss = loss + self.direction_weight * direction_cross_entropy(q, demo)
        with torch.no_grad():       # the cross-entropy leaves stop to the TD loss: judge its pushes alone
            allowed = pushes if self.kind == "push_cross_entropy" else mask
            greedy = q.masked_fill(~allowed, torch.finfo(q.dtype).min).argmax(-1)
            agree = (greedy == demo).float().mean()
            near = _near(greedy, demo).float().mean()
        return TensorDict({"loss_demo": self.weight * (loss + stop_loss), "demo_agreement": agree, "demo_near": near,
                           "demo_stop_agreement": stop_agree}, [])

    def _stop_decision(self, q, pushes, demo, ok) -> tuple[torch.Tensor, torch.Tensor]:
        """Large margin on stop vs the best allowed push (0 when ``stop_margin`` is 0), and agreement."""
        best_push = q.masked_fill(~pushes, torch.finfo(q.dtype).min).max(-1).values
        q_stop, is_stop = q[:, actions.STOP], demo == actions.STOP
        valid = ok & pushes.any(-1)
        agree = ((q_stop > best_push) == is_stop)[valid].float().mean() if valid.any() else q.new_zeros(())
        if self.stop_margin == 0 or not valid.any():
            return q.sum() * 0.0, agree.detach()
        hinge = torch.where(is_stop, best_push + self.stop_margin - q_stop, q_stop + self.stop_margin - best_push)
        return hinge.clamp(min=0)[valid].mean(), agree.detach()


def direction_cross_entropy(q: torch.Tensor, demo: torch.Tensor) -> torch.Tensor:
    """Cross-entropy of the 8 directions' Q [N, A] at each demonstrated push's start cell against its
    direction; demonstrated stops are left out (0 when there are none)."""
    push = demo != actions.STOP
    if not push.any():
        return q.sum() * 0.0
    per = actions.GRID * actions.GRID
    q, demo = q[push], demo[push]
    at_cell = q[:, : actions.NUM_PUSHES].reshape(-1, actions.DIRECTIONS, per)[torch.arange(len(demo)), :, demo % per]
    return F.cross_entropy(at_cell, demo // per)


def smoothed_push_target(demo: torch.Tensor, allowed: torch.Tensor, sigma: float) -> torch.Tensor:
    """[N, A] distributions: the demonstrated pushes [N] spread over nearby starts in the same direction
    (Gaussian weights of ``sigma`` grid cells), kept to the ``allowed`` [N, A] actions, summing to 1."""
    per = actions.GRID * actions.GRID
    d, row, col = demo // per, (demo % per) // actions.GRID, demo % actions.GRID
    grid = torch.arange(actions.GRID, device=demo.device, dtype=torch.float32)
    w_row = torch.exp(-(grid[None] - row[:, None]) ** 2 / (2 * sigma ** 2))
    w_col = torch.exp(-(grid[None] - col[:, None]) ** 2 / (2 * sigma ** 2))
    target = torch.zeros(len(demo), actions.DIRECTIONS, actions.GRID, actions.GRID, device=demo.device)
    target[torch.arange(len(demo)), d] = w_row[:, :, None] * w_col[:, None, :]
    target = torch.cat([target.reshape(len(demo), -1), target.new_zeros(len(demo), allowed.shape[-1] - actions.NUM_PUSHES)], -1)
    target = target * allowed
    target[torch.arange(len(demo)), demo] = target[torch.arange(len(demo)), demo].clamp(min=1e-6)  # never empty
    return target / target.sum(-1, keepdim=True)


def _near(a: torch.Tensor, b: torch.Tensor, cells: int = 2) -> torch.Tensor:
    stop_a, stop_b = a == actions.STOP, b == actions.STOP
    a, b = a.clamp(max=actions.NUM_PUSHES - 1), b.clamp(max=actions.NUM_PUSHES - 1)
    per = actions.GRID * actions.GRID
    same_dir = a // per == b // per
    ra, ca, rb, cb = (a % per) // actions.GRID, a % actions.GRID, (b % per) // actions.GRID, b % actions.GRID
    close = ((ra - rb).abs() <= cells) & ((ca - cb).abs() <= cells)
    return (stop_a & stop_b) | (~stop_a & ~stop_b & same_dir & close)
