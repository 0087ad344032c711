"""What the counting perception sees, as one image for the dashboards: for a few fixed held-out frames, the render,
its most likely class per cell (the bin black, each class its own colour) and its density of countable objects (a heat
map, the frame's expected object count printed on it). Logged at every evaluation of ``recipes/train_perception.py``,
so a run's maps can be watched sharpening beside its count accuracy.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch

from mqa_rl import keys
from mqa_rl.modules.answering.perception import CountingPerception

TILE = 160


def class_palette(num_classes: int) -> np.ndarray:
    """uint8 [K, 3] RGB: class 0 (bin and floor) black, the others evenly spaced hues at full brightness."""
    hues = (np.arange(num_classes) * 180 // max(num_classes - 1, 1)).astype(np.uint8)
    hsv = np.stack([hues, np.full_like(hues, 220), np.full_like(hues, 255)], -1)[None]
    palette = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0]
    palette[0] = 0
    return palette


def _tile(image: np.ndarray, text: str = "") -> np.ndarray:
    tile = cv2.resize(np.ascontiguousarray(image), (TILE, TILE), interpolation=cv2.INTER_NEAREST)
    if text:
        cv2.putText(tile, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
    return tile


@torch.no_grad()
def perception_maps(model: CountingPerception, frames, device, count: int = 4) -> np.ndarray:
    """uint8 RGB [count·TILE, 3·TILE, 3]: a row per frame of ``frames`` (the first ``count``): render | classes |
    density."""
    frames = frames[:count]
    was_training = model.training
    model.eval()
    depth = frames.get(keys.DEPTH).to(device) if model.depth else None
    probs, _, density = model.predict(frames.get(keys.RGB).to(device), depth)
    model.train(was_training)
    palette = class_palette(probs.shape[1])
    rows = []
    for rgb, p, d in zip(frames.get(keys.RGB), probs.cpu(), density.cpu()):
        classes = palette[p.argmax(0).numpy()]
        objects = d[0] * (1 - p[0])                                 # density on cells not the bin
        heat = (objects / objects.max().clamp_min(1e-6)).numpy()
        heat = cv2.applyColorMap((heat * 255).astype(np.uint8), cv2.COLORMAP_INFERNO)[..., ::-1]
        rows.append(np.concatenate([_tile(rgb.numpy().transpose(1, 2, 0), "render"), _tile(classes, "classes"),
                                    _tile(heat, f"density: {float(objects.sum()):.1f} objects")], 1))
    return np.concatenate(rows, 0)
