"""The paper's reward shaping as composable TorchRL transforms.

Each term (R_e, R_g, R_l, ours R_s and R_c, the simple-scene flag, β) is a transform writing its own key under
``"reward_terms"``; ``MQAReward`` combines them into ``reward`` with the stop / simple-scene rule.
``make_reward_transform`` builds a stack from a config; ``mqa_env.make_mqa_env`` wraps the env in it.
The formulas are in ``functional``. Classes are imported lazily (torchrl is heavy).
"""

_EXPORTS = {
    "RewardTerm": "base",
    "ExplorationReward": "exploration",
    "GlobalOcclusionReward": "occlusion",
    "LocalOcclusionReward": "occlusion",
    "SceneOcclusionReward": "occlusion",
    "CountableTargetsReward": "countable",
    "SimpleSceneFlag": "simple_scene",
    "BetaSchedule": "beta",
    "MQAReward": "mqa_reward",
    "make_reward_transform": "factory",
    "register_term": "factory",
    "TERM_REGISTRY": "factory",
}
__all__ = list(_EXPORTS)


def __getattr__(name):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(f"mqa_rl.transforms.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'mqa_rl.transforms' has no attribute {name!r}")
