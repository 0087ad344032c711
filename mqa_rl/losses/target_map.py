"""Auxiliary loss: where are the question's targets? (``PushQNet.target_logits`` vs the segmentation)

The paper's Q-network learns to recognise the asked-about class from the DQN reward alone: a few
scalar rewards per episode for a 20-class recognition problem across a 28 × 28 map. Here the
question's attention over the recognised classes (``PushQNet`` with ``class_map``) also predicts, per grid
cell, the fraction of pixels where a target is visible (``keys.TARGET_CELLS``, from the simulator's segmentation, stored with
each transition). The segmentation is a training signal only, as in EmbodiedQA's CNN pretraining
and UNREAL's auxiliary tasks: the policy still acts from rgb, depth and the question.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from torchrl.objectives import LossModule

from mqa_rl import keys


class TargetMapLoss(LossModule):
    """``weight`` · binary cross-entropy of ``net.target_logits`` against the visible-target fractions.

    Holds the same ``PushQNet`` as the DQN loss's actor (not a copy): its gradient reaches the
    shared trunks and fusion layers. Writes ``loss_target_map`` (weighted) and, for the logs,
    ``target_map_iou`` (cells > 0.5 predicted vs cells with any target pixel ≥ 25 %).
    """

    def __init__(self, net: torch.nn.Module, weight: float = 1.0):
        super().__init__()
        if getattr(net, "class_head", None) is None:
            raise ValueError("TargetMapLoss needs a PushQNet built with class_map=True (model.class_map=true)")
        if not weight > 0:
            raise ValueError(f"the target-map loss weight must be > 0, got {weight}")
        self.net = net
        self.weight = float(weight)

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        if keys.TARGET_CELLS not in tensordict.keys(True):
            raise KeyError(f"{keys.TARGET_CELLS} missing from the sampled transitions: the replay must store it "
                           f"(mqa_rl.collectors.replay.REPLAY_KEYS) and the env must write it (SapienBinEnv does)")
        cells = tensordict.get(keys.TARGET_CELLS).to(torch.float32)
        logits = self.net.target_logits(tensordict.get(keys.RGB), tensordict.get(keys.DEPTH), tensordict.get(keys.QUESTION))
        loss = F.binary_cross_entropy_with_logits(logits, cells.reshape(logits.shape))
        with torch.no_grad():
            pred, true = logits > 0, cells.reshape(logits.shape) >= 0.25
            iou = (pred & true).sum() / (pred | true).sum().clamp(min=1)
        return TensorDict({"loss_target_map": self.weight * loss, "target_map_iou": iou}, batch_size=[])
