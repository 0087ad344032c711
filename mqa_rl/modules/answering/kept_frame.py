"""FrameKeeper: which frame of an episode the answer reads as I_stop.

The paper's VQA reads the first and the last image. A push can bury what an earlier push showed, and the robot has
seen every frame on its way: the paper's future work asks it to "remember" what it did. The keeper chooses the frame
where the counting perception reads the most of the asked class (its expected count; ties: the later frame), since a
visible count only falls short of the answer when targets hide. It reads the frames the VQA reads (the answer
camera's when the observation carries them), and the simulator's measurements of that state go with it, so a
perfect counter on "I_stop" measures the kept frame. Behind a perceiving stop of the same perception file the keeper
reuses the readings the stop left in the states (``keys.PERCEIVED_READING``) and reads only the last frame itself.
"""

from __future__ import annotations

from pathlib import Path
from collections.abc import Sequence

import torch
from tensordict import TensorDictBase

from mqa_rl import keys
from mqa_rl.modules.answering.perceived_count import READING, PerceivedCount, reading_env_kwargs, token_channels

EXPECTED = READING.index("perceived_expected")


class FrameKeeper:
    """``choose(states)`` → the index of the state whose frame the answer reads (0: I_start)."""

    def __init__(self, reading: PerceivedCount, policy=None):
        """``policy``: the policy whose episodes it keeps a frame of; when its learned stop reads the same perception
        file (SHA-256) and classes, the keeper reuses that stop's readings (``self.reuse``)."""
        self.reading = reading.eval()
        stops = getattr(getattr(policy, "critic", None), "reading", None)
        self.reuse = (stops is not None and stops.sha256 is not None and stops.sha256 == reading.sha256
                      and torch.equal(stops.token_channel.cpu(), reading.token_channel.cpu()))

    @classmethod
    def from_file(cls, path: str | Path, dataset, policy=None) -> "FrameKeeper":
        """The perception at ``path``, asked about ``dataset``'s classes (its questions name them)."""
        if not Path(path).is_file():
            raise FileNotFoundError(f"kept_frame={path}: no such perception file; give a counting perception "
                                    f"(e.g. checkpoints/vqa_counting/perception.pt, or one of recipes/train_perception.py)")
        return cls(PerceivedCount.from_file(path, token_channels(dataset), num_classes=len(dataset.classes)), policy)

    def env_kwargs(self, image_size: int) -> dict:
        """The env options the keeper needs: its perception's frames in every observation."""
        return reading_env_kwargs(self.reading, image_size)

    @torch.no_grad()
    def choose(self, states: Sequence[TensorDictBase]) -> int:
        read = [self.reuse and keys.PERCEIVED_READING in s.keys() for s in states]
        expected = torch.empty(len(states))
        for i, s in enumerate(states):
            if read[i]:
                expected[i] = s.get(keys.PERCEIVED_READING)[EXPECTED]
        first: dict[bytes, int] = {}              # a push that moved nothing leaves the same frame: read it once
        same = {}
        for i in range(len(states)):
            if not read[i]:
                same[i] = first.setdefault(self.reading.frames(states[i]).numpy().tobytes(), i)
        todo = sorted(set(same.values()))
        if todo:
            frames = torch.stack([self.reading.frames(states[i]) for i in todo])
            question = states[0].get(keys.QUESTION)
            expected[todo] = self.reading.expected(frames, question.expand(len(todo), *question.shape))
            for i, j in same.items():
                expected[i] = expected[j]
        return last_argmax(expected)


def last_argmax(values: torch.Tensor) -> int:
    """The index of the largest of ``values`` [T], the later one on ties (a later frame has seen more pushes)."""
    return int(torch.nonzero(values >= values.max()).max())


def episode_states(rollout: TensorDictBase) -> list[TensorDictBase]:
    """The states of one episode's rollout [T], I_start first and the last ``next`` last: the roots, which carry what
    the policy wrote (a perceiving stop's reading), then the state the last step led to."""
    return [*rollout.unbind(0), rollout["next"][-1]]
