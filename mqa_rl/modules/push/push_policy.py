"""The push Q-network as TorchRL modules: a greedy ``QValueActor`` and its ε-greedy explorer.

Both honour the env's ``action_mask`` when ``masked`` (the default): the greedy argmax and the
random draws only pick pushes starting over the bin floor, or stop. The explorer's spec is a copy
of the env's action spec (``EGreedyModule`` writes the mask into its spec).
"""

from __future__ import annotations

from collections.abc import Mapping

from tensordict.nn import TensorDictSequential
from torchrl.data import Composite
from torchrl.modules import EGreedyModule, QValueActor

from mqa_rl import keys
from mqa_rl.modules.push.push_qnet import PushQNet

QNET_OPTIONS = {"trunk", "weights", "light_channels", "light_downsample", "fuse_channels", "question_dim", "head_channels",
                "head_context", "coords", "depth_scale", "freeze_trunk", "class_map", "rotated_head", "geometric_push"}
LOADED_BY_RECIPE = {"name", "masked", "pretrained", "pretrained_frozen"}   # not PushQNet arguments
# Options removed after they did not help (docs/notebook/policy.md names the commit that has them). A
# saved run's config (the shipped ones included) may name them at these values, which built the same network.
RETIRED_OPTIONS = {"target_head": False, "film": False, "geometric_stop": False, "boundary_map": False, "head_dilation": 1,
                   "perceived_classes": None}


def make_push_qnet(cfg: Mapping, *, vocab_size: int, camera_distance: float, num_classes: int = 20) -> PushQNet:
    """``PushQNet`` from a model config (``recipes/conf/trunk/*.yaml``); sizes come from the env and dataset."""
    cfg = dict(cfg)
    on = sorted(f"{k}={cfg[k]}" for k in RETIRED_OPTIONS.keys() & cfg.keys() if cfg[k] != RETIRED_OPTIONS[k])
    if on:
        raise ValueError(f"model options {on} were removed (they did not help; docs/notebook/policy.md "
                         f"names the commit that has them): drop them from the config")
    cfg = {k: v for k, v in cfg.items() if k not in RETIRED_OPTIONS}
    unknown = set(cfg) - QNET_OPTIONS - LOADED_BY_RECIPE
    if unknown:
        raise ValueError(f"unknown model config keys {sorted(unknown)}; allowed: {sorted(QNET_OPTIONS | LOADED_BY_RECIPE)}")
    kwargs = {k: (tuple(v) if isinstance(v, list) else v) for k, v in cfg.items() if k in QNET_OPTIONS}
    return PushQNet(vocab_size, camera_distance=camera_distance, num_classes=num_classes, **kwargs)


def make_q_actor(net: PushQNet, action_spec, masked: bool = True) -> QValueActor:
    """Greedy policy: writes ``action``, ``action_value`` and ``chosen_action_value``."""
    return QValueActor(net, in_keys=[keys.RGB, keys.DEPTH, keys.QUESTION], spec=Composite(action=action_spec.clone()),
                       action_space="categorical", action_mask_key=keys.ACTION_MASK if masked else None)


def make_explorer(actor: QValueActor, action_spec, *, eps_init: float, eps_end: float, annealing_frames: int,
                  masked: bool = True) -> TensorDictSequential:
    """``actor`` followed by ε-greedy (ε from ``eps_init`` to ``eps_end`` over ``annealing_frames`` frames)."""
    greedy = EGreedyModule(spec=action_spec.clone(), eps_init=eps_init, eps_end=eps_end,
                           annealing_num_steps=annealing_frames, action_mask_key=keys.ACTION_MASK if masked else None)
    return TensorDictSequential(actor, greedy)

