"""PerceivedCount: the counting perception's reading of the asked class, as features of a learned stop.

Why: the stop's own features read the push policy's coarse geometry maps, which say little about whether the
targets are countable; the counting perception (``checkpoints/vqa_counting/perception.pt``) counts them
as the VQA will. A stop critic fitted with this reading beside the shipped features left fewer targets below the
counter's line at its stop on held-out training scenes, medium and hard beyond noise (a 5-fold refit by scene on the
448-px perception; docs/notebook/policy.md). It reads the frame
the VQA reads: the env's answer camera when the perception was trained at a finer render (the env's
``answer_observation``), else ``rgb``.

The asked class comes from the question's tokens: each token that only questions about one class contain names it
(``token_channels``, built once from the dataset the stop is fitted on and stored with the critic).
"""

from __future__ import annotations

import hashlib
from collections import defaultdict
from pathlib import Path

import torch
from tensordict import TensorDictBase
from torch import nn

from mqa_rl import keys
from mqa_rl.modules.answering.perception import CountingPerception, check_library, load_perception
from mqa_rl.modules.answering.vote_counting import MAX_COUNT, TOP, expected_counts

READING = ("perceived_count", *(f"perceived_mass_{i}" for i in range(1, TOP + 1)), "perceived_log_area",
           "perceived_expected", "perceived_objects")


def token_channels(dataset) -> torch.Tensor:
    """int64 [vocabulary]: for each question token, the class channel (1 + index into ``dataset.classes``) of the
    one class whose questions alone contain it; 0 for the template's words. ValueError when a class has no such token."""
    named = defaultdict(set)
    for q in dataset.questions:
        if len(q.classes) == 1:
            for t in q.tokens:
                named[int(t)].add(q.classes[0])
    table = torch.zeros(len(dataset.vocab), dtype=torch.int64)
    for token, classes in named.items():
        if len(classes) == 1:
            table[token] = 1 + dataset.classes.index(next(iter(classes)))
    asked = set().union(*named.values())
    missing = sorted(asked - {dataset.classes[c - 1] for c in table.unique().tolist() if c > 0})
    if missing:
        raise ValueError(f"no question token names class(es) {missing} alone: the questions of {dataset.root} cannot "
                         f"tell the asked class")
    return table


def file_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


class PerceivedCount(nn.Module):
    """(frames uint8 [B, 3, S, S], question tokens [B, L]) → [B, len(READING)]: the asked class's count, its largest
    vote-cluster masses, log area and expected count, and the image-wide expected count / 50. ``path`` and
    ``sha256``: the perception's file, when it came from one (what a stop critic's file records)."""

    def __init__(self, perception: CountingPerception, token_channel: torch.Tensor, path: str | None = None,
                 sha256: str | None = None):
        super().__init__()
        self.perception = perception.eval()
        self.register_buffer("token_channel", token_channel.to(torch.int64))
        self.path, self.sha256 = path, sha256

    @classmethod
    def from_file(cls, path: str | Path, token_channel: torch.Tensor, sha256: str | None = None,
                  num_classes: int | None = None) -> "PerceivedCount":
        """The perception at ``path``; ValueError when ``sha256`` is given and the file is another one, or when
        ``num_classes`` (the dataset's) is given and the perception knows another object library."""
        model, _ = load_perception(path)
        if num_classes is not None:
            check_library(model, num_classes, path)
        found = file_sha256(path)
        if sha256 is not None and found != sha256:
            raise ValueError(f"{path} is not the perception this stop was fitted with (its SHA-256 differs): restore "
                             f"that file or refit the stop with recipes/fit_stop.py perception={path}")
        return cls(model, token_channel, str(path), found)

    @property
    def input_size(self) -> int:
        return int(self.perception.input_size)

    def asked_channel(self, question: torch.Tensor) -> torch.Tensor:
        """[B] the channel of the first class-naming token of each question."""
        question = question.clamp(0, self.token_channel.numel() - 1)
        named = self.token_channel[question]                                   # [B, L]
        first = (named > 0).to(torch.int64).argmax(-1, keepdim=True)
        channel = named.gather(-1, first).squeeze(-1)
        if bool((channel == 0).any()):
            raise ValueError("a question names no class this stop knows: the perceived count reads the class a "
                             "question asks about (fit the stop on the dataset whose questions it answers)")
        return channel

    def frames(self, td: TensorDictBase) -> torch.Tensor:
        """The frames to read from ``td``: the answer camera's when the observation has it (the frames the VQA
        reads), else ``rgb``; either at least as fine as the perception's input (it resizes them to it)."""
        size = self.input_size
        for key in (keys.ANSWER_RGB, keys.RGB):
            if key in td.keys() and td.get(key).shape[-1] >= size:
                return td.get(key)
        raise ValueError(f"this stop reads the counting perception at {size} px and the observation has no {size}-px "
                         f"frame: run the env with answer_size={size} and answer_observation=true "
                         f"(recipes: collection.env.answer_size={size})")

    @torch.no_grad()
    def forward(self, frames: torch.Tensor, question: torch.Tensor) -> torch.Tensor:
        batch = frames.shape[:-3]
        frames, question = frames.reshape(-1, *frames.shape[-3:]), question.reshape(-1, question.shape[-1])
        feats = self.perception.count_features(frames)                          # [B, K, F]
        row = feats[torch.arange(feats.shape[0]), self.asked_channel(question)]
        count = row[:, :MAX_COUNT + 1].argmax(-1, keepdim=True).float()
        return torch.cat([count, row[:, MAX_COUNT + 1:], feats[:, 0, :1]], -1).reshape(*batch, len(READING))

    @torch.no_grad()
    def expected(self, frames: torch.Tensor, question: torch.Tensor) -> torch.Tensor:
        """[B] the asked class's expected count (``forward``'s ``perceived_expected``, the same value) without the
        vote clustering the other entries need: what a frame keeper compares."""
        probs, _, density = (t.float().cpu() for t in self.perception.predict(frames))
        asked = self.asked_channel(question.reshape(-1, question.shape[-1]))
        return expected_counts(probs, density)[torch.arange(len(asked)), asked - 1]

    def read(self, td: TensorDictBase) -> torch.Tensor:
        return self(self.frames(td), td.get(keys.QUESTION))


def reading_env_kwargs(reading: PerceivedCount | None, image_size: int) -> dict:
    """The env options a perceived count needs: its perception's frames in every observation (the answer camera at
    the perception's size, when that is finer than ``image_size``); {} when it reads ``rgb`` or there is none."""
    if reading is None or reading.input_size <= int(image_size):
        return {}
    return {"answer_size": reading.input_size, "answer_observation": True}
