"""``VQALoss``: cross-entropy of the VQA's answer logits against the oracle answer, as a TorchRL
``LossModule``; it also reports the batch's accuracy (not differentiated).

    loss = VQALoss(vqa_module(model))                  # mqa_rl.modules.answering.vqa.vqa_module
    out = loss(batch)                                  # batch: question, both frames, answer_label
    out["loss_vqa"].backward(); out["accuracy"]

The keys it reads are declared once in ``_AcceptedKeys`` (rename with ``loss.set_keys(answer=...)``).
``label_smoothing`` (0 by default) spreads a little target mass over the other answers.

``grounding`` (a module writing ``GROUNDING_LOGITS``: ``mqa_rl.modules.answering.vqa.grounding_module``) adds
``loss_grounding``: cross-entropy of each of the first heads' class choice against the classes the
question names (``QUESTION_CLASSES``: head h ↔ the h-th class), times ``grounding_weight``, and reports
``grounding_accuracy``. The question's classes are part of the dataset (its programs), like the
segmentation the encoder pretrains on; learnt from the answers alone the choice stayed near uniform.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torchrl.objectives import LossModule

from mqa_rl import keys


class VQALoss(LossModule):
    @dataclass
    class _AcceptedKeys:
        """answer: the oracle answer's index (int64 [B]); logits: where the network writes its answer logits."""

        answer: NestedKey = keys.ANSWER_LABEL
        logits: NestedKey = keys.ANSWER_LOGITS
        question_classes: NestedKey = keys.QUESTION_CLASSES
        grounding: NestedKey = keys.GROUNDING_LOGITS

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys

    def __init__(self, network: TensorDictModule, *, label_smoothing: float = 0.0,
                 grounding: TensorDictModule | None = None, grounding_weight: float = 1.0):
        super().__init__()
        if not 0.0 <= label_smoothing < 1.0:
            raise ValueError(f"label_smoothing={label_smoothing} must lie in [0, 1)")
        if not grounding_weight >= 0.0:
            raise ValueError(f"grounding_weight={grounding_weight} must be ≥ 0")
        self.network = network
        self.grounding = grounding
        self.grounding_weight = float(grounding_weight)
        self.label_smoothing = float(label_smoothing)

    @property
    def out_keys(self):
        extra = ["loss_grounding", "grounding_accuracy"] if self.grounding is not None else []
        return ["loss_vqa", "accuracy", *extra]

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass

    @property
    def in_keys(self):
        extra = [self.tensor_keys.question_classes] if self.grounding is not None else []
        return [*self.network.in_keys, self.tensor_keys.answer, *extra]

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        td = self.network(tensordict.copy())
        logits = td.get(self.tensor_keys.logits)
        target = td.get(self.tensor_keys.answer).reshape(-1)
        loss = F.cross_entropy(logits.reshape(target.shape[0], -1), target, label_smoothing=self.label_smoothing)
        with torch.no_grad():
            accuracy = (logits.reshape(target.shape[0], -1).argmax(-1) == target).float().mean()
        out = {"loss_vqa": loss, "accuracy": accuracy}
        if self.grounding is not None:
            out.update(self._grounding(tensordict))
        return TensorDict(out, batch_size=[])

    def _grounding(self, tensordict: TensorDictBase) -> dict[str, torch.Tensor]:
        if self.tensor_keys.question_classes not in tensordict.keys(True):
            raise KeyError(f"the grounding loss needs {self.tensor_keys.question_classes!r} in the batch (the classes each "
                           f"question names: mqa_rl.training.vqa_data.question_class_labels)")
        choice = self.grounding(tensordict.select(*self.grounding.in_keys).copy()).get(self.tensor_keys.grounding)
        labels = tensordict.get(self.tensor_keys.question_classes).long()
        heads = min(choice.shape[-2], labels.shape[-1])
        choice = choice[..., :heads, :].reshape(-1, choice.shape[-1])
        labels = labels[..., :heads].reshape(-1)
        named = labels >= 0
        if not named.any():
            zero = choice.sum() * 0.0
            return {"loss_grounding": zero, "grounding_accuracy": zero.detach()}
        loss = F.cross_entropy(choice[named], labels[named])
        with torch.no_grad():
            accuracy = (choice[named].argmax(-1) == labels[named]).float().mean()
        return {"loss_grounding": self.grounding_weight * loss, "grounding_accuracy": accuracy}
