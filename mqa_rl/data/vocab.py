"""Word-level question vocabulary and the answer vocabulary, stored with the dataset."""

from __future__ import annotations

import re
from dataclasses import dataclass

PAD, UNK = "<pad>", "<unk>"
ANSWERS = ("0", "1", "2", "3", "yes", "no")
_TOKEN = re.compile(r"[a-z0-9]+|[^\sa-z0-9]")


def words(text: str) -> list[str]:
    """Lower-cased words, with punctuation as separate tokens: "How many cans?" → how many cans ?"""
    return _TOKEN.findall(text.lower())


@dataclass(frozen=True)
class Vocabulary:
    """Token ids: 0 is padding, 1 unknown, then words in sorted order (stable across runs)."""

    itos: tuple[str, ...]

    @classmethod
    def build(cls, texts) -> "Vocabulary":
        found = sorted({w for t in texts for w in words(t)})
        return cls((PAD, UNK, *found))

    def __post_init__(self):
        if self.itos[:2] != (PAD, UNK):
            raise ValueError(f"a vocabulary starts with {PAD!r}, {UNK!r}; got {self.itos[:2]}")
        object.__setattr__(self, "_stoi", {w: i for i, w in enumerate(self.itos)})

    def __len__(self) -> int:
        return len(self.itos)

    @property
    def pad_id(self) -> int:
        return 0

    def encode(self, text: str) -> list[int]:
        return [self._stoi.get(w, 1) for w in words(text)]

    def decode(self, tokens) -> str:
        return " ".join(self.itos[int(t)] for t in tokens if int(t) != 0)
