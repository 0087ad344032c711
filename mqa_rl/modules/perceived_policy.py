"""An image policy: the countable image teacher's rule applied to what the counting perception sees.

The countable image teacher (``PrivilegedPushPolicy(order="visible_first", geometry="visible",
min_visible_fraction=0)``) pushes away what covers a *fragment* of a target the image shows below the perfect
counter's 20-px line; on the training piles it lifts a perfect counter's reading of I_stop over no manipulation
on medium and hard with < 1 push per episode (docs/policy.md, "Where, or which"), while the simulator's own
segmentation tells it which pixels are a target. Here the counting perception (``modules.perception``) tells it
instead, so that nothing but the rgb-d image and the question is read: its class map, split into connected
regions, stands for the objects; a region of the asked class of at least ``min_region_px`` whose density mass
(one unit per object the counter counts) stays below ``min_mass`` is a fragment not yet counted; the depth image says which neighbour
stands higher and covers it. The question's class comes from the dataset's question record (what the question
says), never from the scene.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import torch
from tensordict import TensorDictBase

from mqa_rl import keys
from mqa_rl.modules.perception import load_perception
from mqa_rl.modules.privileged_policy import PrivilegedPushPolicy


class PerceivedCountablePolicy:
    """``td = policy(td)`` writes ``action`` from ``rgb``, ``depth``, the question's index and the push count.

    ``classes``: the dataset's class names (the perception's channels 1…K-1, 0 = the bin); ``questions``: the
    dataset's questions (each names its classes)."""

    def __init__(self, perception: str | Path, classes, questions, min_mass: float = 0.5, min_region_px: float = 8.0,
                 border_px: int = 4, max_tries_per_occluder: int = 2):
        if not 0.0 < min_mass <= 1.0:
            raise ValueError(f"min_mass={min_mass}: a region counts as a counted object from this much density mass "
                             f"(one unit per object); choose it in (0, 1]")
        self.model, _ = load_perception(perception)
        if self.model.num_classes != 1 + len(classes):
            raise ValueError(f"the perception {perception} reads {self.model.num_classes - 1} classes, the dataset has "
                             f"{len(classes)}: use a perception trained on this dataset's objects")
        if min_region_px < 0:
            raise ValueError(f"min_region_px={min_region_px} must be >= 0 pixels of the 224-px render")
        self.classes, self.questions, self.min_mass = list(classes), questions, float(min_mass)
        self.min_region_px = float(min_region_px)
        self.rule = PrivilegedPushPolicy(None, lookahead=1, order="visible_first", geometry="visible",
                                         min_visible_fraction=0.0, border_px=border_px,
                                         max_tries_per_occluder=max_tries_per_occluder)

    def scene(self, td: TensorDictBase) -> dict:
        """The scene as the rule reads it (``PrivilegedPushPolicy.candidates``), from the perception alone."""
        with torch.no_grad():
            probs, _, density = self.model.predict(td[keys.RGB][None])
        probs, density = probs[0].numpy(), density[0, 0].numpy()
        labels = probs.argmax(0)
        question = int(td[keys.QUESTION_INDEX].reshape(-1)[0])
        asked = {1 + self.classes.index(c) for c in self.questions[question].classes}
        seg = np.zeros(labels.shape, np.int32)
        target, area, mass = [], [], []
        for k in range(1, probs.shape[0]):
            n, regions = cv2.connectedComponents((labels == k).astype(np.uint8), connectivity=8)
            for r in range(1, n):
                inside = regions == r
                seg[inside] = len(target) + 1
                target.append(k in asked)
                area.append(float(inside.sum()) * self.model.cell_px)
                mass.append(float((density[inside] * probs[k][inside]).sum()))
        depth = td[keys.DEPTH][0].numpy()
        scale = depth.shape[0] // seg.shape[0]
        seg = np.kron(seg, np.ones((scale, scale), np.int32))       # the class map's cells onto the image's pixels
        area, mass = np.asarray(area, np.float32), np.asarray(mass, np.float32)
        return {"seg": seg, "entity_ids": np.arange(1, len(target) + 1), "target": np.asarray(target, bool),
                "visible": area, "full": area, "counted": (mass >= self.min_mass) | (area < self.min_region_px),
                "depth": depth,
                "question_id": question, "scene_id": None, "push_count": int(td[keys.PUSH_COUNT].reshape(-1)[0])}

    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        td.set(keys.ACTION, torch.tensor(self.rule.choose(self.scene(td)), dtype=torch.int64))
        return td
