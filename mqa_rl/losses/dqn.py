"""TorchRL's ``DQNLoss`` for the push Q-map, with its target-network updater.

Double DQN picks the next action with the online network (masked argmax: the actor honours
``("next", "action_mask")``) and values it with the target network. The loss writes the squared TD
error to ``td_error``, the replay priority.
"""

from __future__ import annotations

from collections.abc import Mapping

from torchrl.objectives import DQNLoss, HardUpdate, SoftUpdate

LOSS_FUNCTIONS = {"huber": "smooth_l1", "smooth_l1": "smooth_l1", "mse": "l2", "l2": "l2"}


def make_dqn_loss(actor, cfg: Mapping) -> tuple[DQNLoss, HardUpdate | SoftUpdate]:
    """(loss, target updater) from the ``loss`` config: gamma, function, double_dqn, target update."""
    function = str(cfg.get("function", "huber")).lower()
    if function not in LOSS_FUNCTIONS:
        raise ValueError(f"loss.function={function!r}; choose one of {sorted(LOSS_FUNCTIONS)}")
    gamma = float(cfg.get("gamma", 0.6))
    if not 0.0 <= gamma < 1.0:
        raise ValueError(f"loss.gamma={gamma} must lie in [0, 1)")
    loss = DQNLoss(actor, loss_function=LOSS_FUNCTIONS[function], delay_value=True,
                   double_dqn=bool(cfg.get("double_dqn", True)))
    loss.make_value_estimator(gamma=gamma)
    target = dict(cfg.get("target_update", {"kind": "hard", "interval": 100}))
    kind = target.get("kind", "hard")
    if kind == "hard":
        updater = HardUpdate(loss, value_network_update_interval=int(target.get("interval", 100)))
    elif kind == "soft":
        updater = SoftUpdate(loss, tau=float(target.get("tau", 0.005)))
    else:
        raise ValueError(f"loss.target_update.kind={kind!r}; choose 'hard' (with interval) or 'soft' (with tau)")
    return loss, updater
