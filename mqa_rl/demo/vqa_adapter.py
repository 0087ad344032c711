"""The one place the demo touches the VQA model (``mqa_rl.modules.answering.vqa``), through its published contract::

    from mqa_rl.modules.answering.vqa import load_vqa
    model = load_vqa(path)              # FileNotFoundError / ValueError with a clear message
    probs = model.answer_probs(question_tokens,  # LongTensor [B, L]
                               first_rgb,        # uint8 [B, H, W, 3]
                               last_rgb)         # uint8 [B, H, W, 3]  -> FloatTensor [B, n_answers]
    model.answers                        # list[str], the answer vocabulary

The module is imported lazily: without it, or without a usable checkpoint, the demo still runs and
says ``no VQA checkpoint: <why>`` where the answer would be. Models are loaded once per server.
"""

from __future__ import annotations

import logging
from pathlib import Path

import torch

log = logging.getLogger(__name__)
NO_VQA = "no VQA checkpoint"
TRAIN_HINT = ("train one with `python recipes/train_vqa.py system=<name>` and start the demo with "
              "`vqa=[path/to/checkpoint]`")


def _load_vqa():
    from mqa_rl.modules.answering.vqa import load_vqa      # lazily: without the module the demo still runs

    return load_vqa


def answer_probs(model, tokens: torch.Tensor, first_rgb: torch.Tensor, last_rgb: torch.Tensor) -> dict[str, float]:
    """``{answer: probability}`` for one episode: tokens [L], images uint8 [H, W, 3]."""
    with torch.no_grad():
        probs = model.answer_probs(tokens.long()[None], first_rgb[None], last_rgb[None])
    answers = list(model.answers)
    if probs.shape != (1, len(answers)):
        raise ValueError(f"the VQA returned probabilities of shape {tuple(probs.shape)} for {len(answers)} answers")
    return {a: float(p) for a, p in zip(answers, probs[0].tolist())}


def trained_types(model, path: Path) -> list[str] | None:
    """The question types a VQA learnt from: its meta (train_vqa.py records them), else the questions group of
    the run's ``config.yaml`` beside the checkpoint (older runs); None when neither says."""
    types = getattr(model, "meta", {}).get("question_types")
    if types is None:
        config = (path if path.is_dir() else path.parent) / "config.yaml"
        try:
            from omegaconf import OmegaConf

            types = OmegaConf.to_container(OmegaConf.load(config)).get("questions", {}).get("types")
        except Exception:                                 # noqa: BLE001 - no readable record: no warning, still usable
            return None
    return [str(t) for t in types] if types else None


class VQARegistry:
    """VQA checkpoints by display name (loaded at start), and those that cannot be used, with why."""

    def __init__(self, paths=()):
        self.models: dict[str, object] = {}
        self.problems: list[tuple[str, str]] = []
        self.types: dict[str, list[str] | None] = {}
        paths = [Path(p) for p in paths or ()]
        if not paths:
            return
        try:
            load_vqa = _load_vqa()
        except ImportError as error:
            for p in paths:
                self.problems.append((str(p), f"the VQA module mqa_rl.modules.answering.vqa is not in this version "
                                              f"({error})"))
            return
        for p in paths:
            try:
                name = p.name if p.name not in self.models else str(p)
                self.models[name] = load_vqa(p)
                self.types[name] = trained_types(self.models[name], p)
            except Exception as error:                        # noqa: BLE001 - listed, never fatal
                log.warning("VQA checkpoint %s unusable: %s", p, error)
                self.problems.append((str(p), f"{type(error).__name__}: {str(error)[:400]}"))

    @property
    def names(self) -> list[str]:
        return list(self.models)

    def missing_reason(self) -> str:
        """Why no answer can be given, as the demo shows it where the answer would be."""
        if self.problems:
            return f"{NO_VQA}: " + "; ".join(f"{p} unusable ({why})" for p, why in self.problems)
        return f"{NO_VQA}: none configured; {TRAIN_HINT}"

    def answer_size(self, image_size: int) -> int | None:
        """The answer camera the demo's env needs: the finest frames a VQA reads beyond the env's ``image_size``."""
        if not self.models:                  # none loaded (the VQA module may be absent): the env's frames only
            return None
        from mqa_rl.modules.answering.vqa import answer_size_for
        return answer_size_for(self.models.values(), image_size)

    def answer(self, name: str | None, tokens, first_rgb, last_rgb, answer_frames=None) -> dict[str, float] | str:
        """``{answer: probability}``, or the message saying why there is no answer. ``answer_frames``: (I_start,
        I_stop) of the env's answer camera, read instead by a VQA whose frames are that size."""
        if not name or name not in self.models:
            return self.missing_reason() if not self.models else f"{NO_VQA}: none chosen (pick one of {self.names})"
        model = self.models[name]
        if answer_frames is not None and getattr(model, "frame_size", None) == answer_frames[0].shape[0]:
            first_rgb, last_rgb = answer_frames
        try:
            return answer_probs(model, tokens, first_rgb, last_rgb)
        except Exception as error:                            # noqa: BLE001 - a broken model must not end the page
            log.exception("VQA %s failed", name)
            return f"the VQA {name} failed on this episode: {type(error).__name__}: {error}"

    def unlearnt_type(self, name: str | None, question_type: str) -> str | None:
        """A warning when VQA ``name`` never saw a question of ``question_type`` (its answer is a guess)."""
        types = self.types.get(name) if name else None
        if types is None or question_type in types:
            return None
        article = "an" if question_type[:1].lower() in "aeiou" else "a"
        return (f"this VQA learnt from {', '.join(t.upper() for t in types)} questions only: its answer to {article} "
                f"{question_type.upper()} question is a guess (train one with questions=all_types)")

    def status(self) -> str:
        if self.models:
            lines = [f"VQA checkpoints: {', '.join(self.names)}."]
        else:
            lines = [f"**{self.missing_reason()}**"]
        if self.models:
            lines += [f"- unusable `{p}`: {why}" for p, why in self.problems]
        return "\n".join(lines)
