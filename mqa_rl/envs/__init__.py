"""TorchRL environments. ``SapienBinEnv`` is imported lazily (it pulls in SAPIEN and torch)."""

__all__ = ["SapienBinEnv"]


def __getattr__(name):
    if name == "SapienBinEnv":
        from mqa_rl.envs.sapien_bin import SapienBinEnv

        return SapienBinEnv
    raise AttributeError(f"module 'mqa_rl.envs' has no attribute {name!r}")
