"""Build a reward stack from a config (a dict or an omegaconf node), as the recipes do.

Config keys (see ``recipes/conf/reward/*.yaml``)::

    terms:             {name: {constructor kwargs}}   e.g. local_occlusion: {reduce: max}
    question_weights:  {name: weight}                 R_q = Σ weight · term
    simple_threshold:  0.2                            the simple-scene overlap threshold
    beta_horizon:      2000                           T, half the replay memory
    beta_final:        0.5                            β after T (paper 0.5; 0: R_q alone)
    reward_clip:       null                           [lo, hi]: clamp the total (DQN's usual [-1, 1])
    explore_term:      exploration                    the term β weighs (paper: R_e; or scene_occlusion)
    stop_reward / early_stop_penalty / redundant_push_reward

A new term is a ``RewardTerm`` subclass registered with ``register_term(name, cls)``; it can then
be named in ``terms`` and ``question_weights`` without touching the library.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping

import torch
from torchrl.envs import Compose

from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.beta import BetaSchedule
from mqa_rl.transforms.countable import CountableTargetsReward
from mqa_rl.transforms.exploration import ExplorationReward
from mqa_rl.transforms.mqa_reward import MQAReward
from mqa_rl.transforms.occlusion import GlobalOcclusionReward, LocalOcclusionReward, SceneOcclusionReward
from mqa_rl.transforms.simple_scene import SimpleSceneFlag

TERM_REGISTRY: dict[str, type[RewardTerm]] = {
    "exploration": ExplorationReward,
    "global_occlusion": GlobalOcclusionReward,
    "local_occlusion": LocalOcclusionReward,
    "scene_occlusion": SceneOcclusionReward,
    "countable_targets": CountableTargetsReward,
}


def register_term(name: str, cls: type[RewardTerm]) -> None:
    """Make a new reward term available to configs under ``name``."""
    if not (isinstance(cls, type) and issubclass(cls, RewardTerm)):
        raise TypeError(f"{cls!r} is not a RewardTerm subclass")
    TERM_REGISTRY[name] = cls


def _plain(cfg):
    try:
        from omegaconf import OmegaConf

        if OmegaConf.is_config(cfg):
            return OmegaConf.to_container(cfg, resolve=True)
    except ImportError:
        pass
    return cfg


def _mapping(value, what: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ValueError(f"reward config: {what} must be a mapping, got {value!r}")
    return dict(value)


def _make_term(name: str, kwargs) -> RewardTerm:
    """``TERM_REGISTRY[name](**kwargs)``; a keyword the term does not take is refused naming the term."""
    cls = TERM_REGISTRY[name]
    try:
        inspect.signature(cls).bind(**kwargs)
    except TypeError as e:
        params = [p for p in inspect.signature(cls).parameters if p not in ("self", "args", "kwargs")]
        raise ValueError(f"reward term {name!r} ({cls.__name__}): {e}; it takes {params}") from None
    return cls(**kwargs)


def make_reward_transform(cfg: Mapping, *, push_length: float, counter: torch.Tensor | None = None) -> Compose:
    """Terms, simple-scene flag, β and ``MQAReward`` as one ``Compose`` for ``TransformedEnv``."""
    cfg = dict(_plain(cfg))
    allowed = {"terms", "question_weights", "simple_threshold", "beta_horizon", "beta_final", "reward_clip", "explore_term", "stop_reward",
               "early_stop_penalty", "redundant_push_reward", "name", "description"}
    unknown = set(cfg) - allowed
    if unknown:
        raise ValueError(f"unknown reward config keys {sorted(unknown)}; allowed: {sorted(allowed)}")
    terms = _mapping(cfg.get("terms"), "terms")
    terms.setdefault("exploration", {})
    explore = cfg.get("explore_term", "exploration")
    if explore not in TERM_REGISTRY:
        raise ValueError(f"explore_term {explore!r} is not a registered term; registered: {sorted(TERM_REGISTRY)}")
    terms.setdefault(explore, {})
    weights = _mapping(cfg.get("question_weights"), "question_weights")
    missing = set(weights) - set(terms)
    if missing:
        raise ValueError(f"question_weights names terms {sorted(missing)} that are not in 'terms' ({sorted(terms)})")
    transforms = []
    for name, kwargs in terms.items():
        if name not in TERM_REGISTRY:
            raise ValueError(f"unknown reward term {name!r}; registered: {sorted(TERM_REGISTRY)}")
        kwargs = _mapping(kwargs, f"terms.{name}")
        if TERM_REGISTRY[name] is ExplorationReward:
            kwargs.setdefault("push_length", push_length)
        transforms.append(_make_term(name, kwargs))
    transforms.append(SimpleSceneFlag(cfg.get("simple_threshold", 0.2)))
    transforms.append(BetaSchedule(cfg.get("beta_horizon", 2000), counter, final=cfg.get("beta_final", 0.5)))
    transforms.append(MQAReward(
        weights,
        clip=cfg.get("reward_clip"),
        explore_key=TERM_REGISTRY[explore].out_key,
        stop_reward=cfg.get("stop_reward", 1.0),
        early_stop_penalty=cfg.get("early_stop_penalty", -1.0),
        redundant_push_reward=cfg.get("redundant_push_reward", 0.0),
    ))
    return Compose(*transforms)
