"""``VQALoss``: cross-entropy of the VQA's answer logits against the oracle answer, as a TorchRL
``LossModule``; it also reports the batch's accuracy (not differentiated).

    loss = VQALoss(vqa_module(model))                  # mqa_rl.modules.vqa.vqa_module
    out = loss(batch)                                  # batch: question, both frames, answer_label
    out["loss_vqa"].backward(); out["accuracy"]

The keys it reads are declared once in ``_AcceptedKeys`` (rename with ``loss.set_keys(answer=...)``).
``label_smoothing`` (0 by default) spreads a little target mass over the other answers.
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

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    out_keys = ["loss_vqa", "accuracy"]

    def __init__(self, network: TensorDictModule, *, label_smoothing: float = 0.0):
        super().__init__()
        if not 0.0 <= label_smoothing < 1.0:
            raise ValueError(f"label_smoothing={label_smoothing} must lie in [0, 1)")
        self.network = network
        self.label_smoothing = float(label_smoothing)

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass

    @property
    def in_keys(self):
        return [*self.network.in_keys, self.tensor_keys.answer]

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        td = self.network(tensordict.copy())
        logits = td.get(self.tensor_keys.logits)
        target = td.get(self.tensor_keys.answer).reshape(-1)
        loss = F.cross_entropy(logits.reshape(target.shape[0], -1), target, label_smoothing=self.label_smoothing)
        with torch.no_grad():
            accuracy = (logits.reshape(target.shape[0], -1).argmax(-1) == target).float().mean()
        return TensorDict({"loss_vqa": loss, "accuracy": accuracy}, batch_size=[])
