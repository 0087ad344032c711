"""The push Q-network as TorchRL modules: a greedy ``QValueActor`` and its ε-greedy explorer.

A network that reads the perceived classes (``model.perceived_classes``: a counting perception's file) acts
behind ``PerceivedClasses``, which writes them into each state it meets (``PerceivingActor``).

Both honour the env's ``action_mask`` when ``masked`` (the default): the greedy argmax and the
random draws only pick pushes starting over the bin floor, or stop. The explorer's spec is a copy
of the env's action spec (``EGreedyModule`` writes the mask into its spec).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase, TensorDictSequential
from torchrl.data import Composite
from torchrl.modules import EGreedyModule, QValueActor

from mqa_rl import keys
from mqa_rl.modules.perceived_classes import PerceivedClasses
from mqa_rl.modules.push_qnet import PushQNet

QNET_OPTIONS = {"trunk", "weights", "light_channels", "light_downsample", "fuse_channels", "question_dim", "head_channels",
                "head_context", "coords", "depth_scale", "freeze_trunk", "class_map", "rotated_head", "geometric_push",
                "perceived_classes"}
LOADED_BY_RECIPE = {"name", "masked", "pretrained", "pretrained_frozen"}   # not PushQNet arguments
# Options removed after their attempts lost (docs/notebook/policy_attempts.md names the commit that has them). A
# saved run's config (the shipped ones included) may name them at these values, which built the same network.
RETIRED_OPTIONS = {"target_head": False, "film": False, "geometric_stop": False, "boundary_map": False, "head_dilation": 1}


def make_push_qnet(cfg: Mapping, *, vocab_size: int, camera_distance: float, num_classes: int = 20) -> PushQNet:
    """``PushQNet`` from a model config (``recipes/conf/trunk/*.yaml``); sizes come from the env and dataset."""
    cfg = dict(cfg)
    on = sorted(f"{k}={cfg[k]}" for k in RETIRED_OPTIONS.keys() & cfg.keys() if cfg[k] != RETIRED_OPTIONS[k])
    if on:
        raise ValueError(f"model options {on} were removed (their attempts lost; docs/notebook/policy_attempts.md "
                         f"names the commit that has them): drop them from the config")
    cfg = {k: v for k, v in cfg.items() if k not in RETIRED_OPTIONS}
    unknown = set(cfg) - QNET_OPTIONS - LOADED_BY_RECIPE
    if unknown:
        raise ValueError(f"unknown model config keys {sorted(unknown)}; allowed: {sorted(QNET_OPTIONS | LOADED_BY_RECIPE)}")
    kwargs = {k: (tuple(v) if isinstance(v, list) else v) for k, v in cfg.items() if k in QNET_OPTIONS}
    kwargs["perceived_classes"] = bool(cfg.get("perceived_classes"))      # the file is the actor's (make_q_actor)
    return PushQNet(vocab_size, camera_distance=camera_distance, num_classes=num_classes, **kwargs)


def make_q_actor(net: PushQNet, action_spec, masked: bool = True,
                 perceived_classes: str | Path | None = None) -> QValueActor | PerceivingActor:
    """Greedy policy: writes ``action``, ``action_value`` and ``chosen_action_value``; for a network that reads the
    perceived classes, behind ``PerceivedClasses`` of the counting perception at ``perceived_classes``."""
    if net.perceived_classes and not perceived_classes:
        raise ValueError("this network reads the perceived classes (model.perceived_classes): give make_q_actor the "
                         "counting perception's file it reads")
    if perceived_classes and not net.perceived_classes:
        raise ValueError(f"perceived_classes={perceived_classes} given for a network that reads its own class head: "
                         f"build it with model.perceived_classes=<that file>")
    actor = QValueActor(net, in_keys=list(net.in_keys), spec=Composite(action=action_spec.clone()),
                        action_space="categorical", action_mask_key=keys.ACTION_MASK if masked else None)
    if not perceived_classes:
        return actor
    return PerceivingActor(PerceivedClasses.from_file(perceived_classes, net.num_classes), actor)


class PerceivingActor(TensorDictModuleBase):
    """``actor`` behind ``perceiver``: the perceived classes are read where a state lacks them, then the actor acts.
    Unlike a ``TensorDictSequential``, its ``in_keys`` keep the perceived classes, so a loss that selects a network's
    inputs (TorchRL's value estimators) keeps the stored ones instead of reading every sample again."""

    def __init__(self, perceiver: PerceivedClasses, actor: QValueActor):
        super().__init__()
        self.perceiver, self.actor = perceiver, actor
        self.in_keys = list(dict.fromkeys([*actor.in_keys, *perceiver.in_keys]))
        self.out_keys = [*actor.out_keys, *perceiver.out_keys]
        self.spec = actor.spec

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        return self.actor(self.perceiver(tensordict))


def perceiver_of(actor) -> PerceivedClasses | None:
    """The ``PerceivedClasses`` reader in front of a greedy actor (or an explorer over one); None when it has none."""
    return next((m for m in actor.modules() if isinstance(m, PerceivedClasses)), None)


def make_explorer(actor: QValueActor, action_spec, *, eps_init: float, eps_end: float, annealing_frames: int,
                  masked: bool = True) -> TensorDictSequential:
    """``actor`` followed by ε-greedy (ε from ``eps_init`` to ``eps_end`` over ``annealing_frames`` frames)."""
    greedy = EGreedyModule(spec=action_spec.clone(), eps_init=eps_init, eps_end=eps_end,
                           annealing_num_steps=annealing_frames, action_mask_key=keys.ACTION_MASK if masked else None)
    return TensorDictSequential(actor, greedy)

