"""Pushers by name, so configs can choose one (``env.pusher=arm``)."""

from __future__ import annotations

from mqa_rl.sim.pusher import FingerPusher, Pusher

PUSHER_NAMES = ("finger", "arm")


def make_pusher(name: str) -> Pusher:
    """``"finger"``: the force-limited capsule finger; ``"arm"``: the Panda with a stick (needs the optional
    ``mani_skill`` assets: ``pip install 'mqa_rl[arm]'``; a missing package raises ``ArmAssetsMissing`` here)."""
    if name == "finger":
        return FingerPusher()
    if name == "arm":
        from mqa_rl.sim import panda
        from mqa_rl.sim.arm_pusher import ArmPusher

        panda.panda_urdf_path()          # fail now, with the install hint, not at the first reset
        return ArmPusher()
    raise ValueError(f"unknown pusher {name!r}: choose one of {PUSHER_NAMES} (or pass a Pusher object)")
