"""A scene's questions for the picker, and typed questions matched to the dataset's own.

A typed question goes through the dataset's tokenizer (``Vocabulary`` words); it is accepted when it
is, word for word (case and punctuation aside), one of the scene's questions: then the true answer
and the exact tokens the policies and the VQA were trained on come from the dataset. Anything else
raises ``QuestionError`` with what is accepted (unknown words → the vocabulary; a sentence outside
the templates → the four templates and the object names), never a crash.
"""

from __future__ import annotations

from mqa_rl.data.dataset import MQADataset
from mqa_rl.data.questions import QUESTION_TYPES, Question
from mqa_rl.data.vocab import PAD, UNK, words

TEMPLATES = {
    "counting": "How many <objects> are there in the bin?",
    "existence": "Is there <an object> in the bin?",
    "spatial": "Is there <an object> under the <other object>?",
    "logic": "Is there <an object> and <another object> in the bin?",
}


MAX_SHOWN = 120           # characters of a typed question quoted back in a message (a page, not a log)
MAX_UNKNOWN_SHOWN = 8


def _shown(text: str, limit: int = MAX_SHOWN) -> str:
    """``text`` stripped and cut to ``limit`` characters for quoting back to the user."""
    text = text.strip()
    return text if len(text) <= limit else text[:limit - 1] + "…"


class QuestionError(ValueError):
    """A typed question the dataset does not have; the message says what is accepted."""


def _key(text: str) -> tuple[str, ...]:
    return tuple(w for w in words(text) if w.isalnum())       # punctuation does not matter


class SceneQuestions:
    """The dataset's questions by scene and type, and typed-question matching."""

    def __init__(self, dataset: MQADataset):
        self.dataset = dataset
        self._by_scene: dict[str, list[Question]] = {}
        for q in dataset.questions:
            self._by_scene.setdefault(q.scene_id, []).append(q)
        self._index = {q.id: i for i, q in enumerate(dataset.questions)}
        self._known = set(dataset.vocab.itos) - {PAD, UNK}
        self._text_index: dict[str, dict[tuple[str, ...], Question]] = {}

    def of_scene(self, scene_id: str, qtype: str | None = None) -> list[Question]:
        """The scene's questions (all four types, or one); ``KeyError`` for an unknown scene."""
        if scene_id not in self._by_scene:
            raise KeyError(f"unknown scene {scene_id!r}; scenes run {self.dataset.scenes[0].id} … "
                           f"{self.dataset.scenes[-1].id}")
        if qtype is not None and qtype not in QUESTION_TYPES:
            raise ValueError(f"unknown question type {qtype!r}; choose among {list(QUESTION_TYPES)}")
        return [q for q in self._by_scene[scene_id] if qtype is None or q.type == qtype]

    def get(self, question_id: str) -> Question:
        return self.dataset.question(question_id)

    def index(self, question_id: str) -> int:
        """Position in ``MQADataset.questions``."""
        return self._index[question_id]

    def accepted_words(self) -> list[str]:
        return sorted(w for w in self._known if w.isalnum())

    def objects_help(self) -> str:
        return "; ".join(f"{s} / {p}" for s, p in (self.dataset.phrases[c] for c in self.dataset.classes))

    def templates_help(self) -> str:
        return " | ".join(TEMPLATES.values())

    def parse(self, scene_id: str, text: str | None) -> Question:
        """The scene's question that ``text`` spells; ``QuestionError`` saying what is accepted otherwise."""
        key = _key(text or "")
        if not key:
            raise QuestionError("empty question: type one, e.g. \"How many cans are there in the bin?\", "
                                f"or pick one of the scene's questions. Templates: {self.templates_help()}")
        unknown = [w for w in dict.fromkeys(key) if w not in self._known]
        if unknown:
            listed = ", ".join(repr(_shown(w, 30)) for w in unknown[:MAX_UNKNOWN_SHOWN])
            more = f" and {len(unknown) - MAX_UNKNOWN_SHOWN} more" if len(unknown) > MAX_UNKNOWN_SHOWN else ""
            raise QuestionError(f"unknown word(s) {listed}{more}: the questions use only "
                                f"these words: {', '.join(self.accepted_words())}")
        if scene_id not in self._text_index:
            self._text_index[scene_id] = {_key(q.text): q for q in self.of_scene(scene_id)}
        found = self._text_index[scene_id].get(key)
        if found is None:
            raise QuestionError(f"\"{_shown(text)}\" is not one of the dataset's question templates: "
                                f"{self.templates_help()} (two different objects in SPATIAL and LOGIC; "
                                f"singular with 'a'/'an', plural in COUNTING). Objects: {self.objects_help()}")
        return found
