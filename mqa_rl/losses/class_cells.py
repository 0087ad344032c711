"""Pretraining loss of the push Q-network's recognition: which classes fill each action-grid cell.

The target is the simulator's per-cell class fractions (``keys.CLASS_CELLS``, channel 0 = no
object), the prediction ``PushQNet.class_logits`` from rgb alone: a soft cross-entropy per cell.
Dense labels on all 784 cells and 21 classes of every frame teach what the DQN reward (a few scalars
per episode) could not in thousands of updates (docs/results.md, "The paper's three variants").
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.objectives import LossModule

from mqa_rl import keys


class ClassCellsLoss(LossModule):
    """Writes ``loss_class_cells``, and for the logs ``cell_accuracy`` (argmax class right, over cells
    whose main content is an object) and ``target_iou`` (the mean over classes present in the batch of
    the IoU of "class fills ≥ 25 % of the cell", predicted probability vs truth: what the DQN reads)."""

    def __init__(self, net: torch.nn.Module):
        super().__init__()
        if getattr(net, "class_head", None) is None:
            raise ValueError("ClassCellsLoss needs a PushQNet built with class_map=True")
        self.net = net

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        target = tensordict.get(keys.CLASS_CELLS).to(torch.float32)
        logits = self.net.class_logits(tensordict.get(keys.RGB))
        if logits.shape != target.shape:
            raise ValueError(f"class logits {tuple(logits.shape)} vs labels {tuple(target.shape)}: the frames were "
                             f"labelled for {target.shape[1] - 1} classes, the network has {logits.shape[1] - 1}")
        loss = -(target * torch.log_softmax(logits, 1)).sum(1).mean()
        with torch.no_grad():
            prob = torch.softmax(logits, 1)
            main = target.argmax(1)
            objects = main > 0
            accuracy = (prob.argmax(1) == main)[objects].float().mean() if objects.any() else torch.tensor(float("nan"))
            pred, true = prob[:, 1:] >= 0.25, target[:, 1:] >= 0.25
            inter, union = (pred & true).sum((0, 2, 3)), (pred | true).sum((0, 2, 3))
            present = true.sum((0, 2, 3)) > 0
            iou = (inter[present] / union[present].clamp(min=1)).mean() if present.any() else torch.tensor(float("nan"))
        return TensorDict({"loss_class_cells": loss, "cell_accuracy": accuracy, "target_iou": iou}, batch_size=[])
