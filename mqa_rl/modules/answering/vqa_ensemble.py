"""Several VQAs of one system (training seeds) answering as one: the mean of their answer probabilities.

Why: with ~1,200 training episodes a VQA's seed moves a Table III cell by up to 0.16 (docs/results.md,
"Three VQA seeds"), more than any difference between policies; averaging the seeds' probabilities answers
with less of that noise and costs only the extra forward passes. ``recipes/evaluate.py 'vqa_dir=[seed0_dir, seed1_dir]'`` uses it.
It honours the public contract of ``mqa_rl.modules.answering.vqa`` (``answer_probs``, ``answers``, ``tokenize``,
``check_dataset``, ``meta``).
"""

from __future__ import annotations

from pathlib import Path

import torch

from mqa_rl.modules.answering.vqa import VQAModel, load_vqa


class VQAEnsemble:
    """``members``: VQAs with the same question and answer vocabularies (ValueError otherwise)."""

    def __init__(self, members: list[VQAModel]):
        if not members:
            raise ValueError("a VQA ensemble needs at least one member")
        first = members[0]
        for model in members[1:]:
            if list(model.vocab) != list(first.vocab) or list(model.answers) != list(first.answers):
                raise ValueError("the ensemble's VQAs were trained with different question or answer vocabularies: "
                                 "give VQAs trained on the same dataset")
            if model.frame_size != first.frame_size:
                raise ValueError(f"the ensemble's VQAs read frames of different sizes ({first.frame_size}, {model.frame_size} "
                                 f"px): give VQAs on the same perception")
        self.members = list(members)
        self.answers, self.vocab = list(first.answers), list(first.vocab)
        self.meta = {**first.meta, "members": [m.meta for m in members]}
        self.frame_size = first.frame_size
        # members on one frozen perception (seeds of a counting head) read the same features: computed once
        self.shared_encoder = all(m.pool == "counts" and m.config["freeze_encoder"] for m in members) and all(
            _same_weights(m.encoder, first.encoder) for m in members[1:])

    @classmethod
    def load(cls, paths: list[str | Path]) -> "VQAEnsemble":
        """The VQAs saved at ``paths`` (each as ``load_vqa`` reads it, with its errors)."""
        return cls([load_vqa(p) for p in paths])

    def tokenize(self, texts) -> torch.Tensor:
        return self.members[0].tokenize(texts)

    def check_dataset(self, dataset) -> None:
        for member in self.members:
            member.check_dataset(dataset)

    def answer_probs(self, question_tokens: torch.Tensor, first_rgb: torch.Tensor, last_rgb: torch.Tensor) -> torch.Tensor:
        """P(answer) [B, len(answers)]: the members' probabilities averaged."""
        if not self.shared_encoder:
            return torch.stack([m.answer_probs(question_tokens, first_rgb, last_rgb) for m in self.members]).mean(0)
        for m in self.members:
            m.check_tokens(question_tokens)
        return self.answer_probs_from_features(question_tokens,
                                               *self.members[0].frame_features(first_rgb, last_rgb, question_tokens.shape[0]))

    def answer_probs_from_features(self, question_tokens: torch.Tensor, first: torch.Tensor, last: torch.Tensor) -> torch.Tensor:
        """``answer_probs`` from the shared perception's ``frame_features`` (``shared_encoder`` only; tokens checked
        by the caller)."""
        return torch.stack([m.answer_probs_from_features(question_tokens, first, last) for m in self.members]).mean(0)

    @property
    def feature_reader(self) -> VQAModel | None:
        """The member whose ``encode_frames`` all members read (seeds of a head on one frozen perception), else None."""
        return self.members[0] if self.shared_encoder else None


def _same_weights(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)
