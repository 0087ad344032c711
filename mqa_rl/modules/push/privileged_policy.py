"""An ORACLE reference policy: it reads the simulator's ground truth, which no real robot has.

It answers "what can manipulation reveal at all on these scenes?": the upper reference row of the
answering table, next to the random baseline and the learned policies. It is never used to train
anything. Each step it looks at the question's target objects; while one of them is not
*revealed* (fewer than ``min_visible_px`` visible pixels, or less than ``min_visible_fraction`` of
its full silhouette), it takes the least visible one, finds the object covering most of that
target's full silhouette in the segmentation, and pushes that occluder straight away from the
target: the push starts just behind the occluder's visible part on the target's side and runs
through it. When every target is revealed (or nothing covers the hidden ones, or every
occluder was already pushed ``max_tries_per_occluder`` times without success) it stops.
``order="visible_first"`` serves the partly visible targets first (most visible first), then the
hidden ones: a teacher whose choices an image policy can see (``recipes/collect.py what=demonstrations``).
``geometry="visible"`` goes further: only targets the image shows a part of are served, the occluders are
the objects whose visible pixels border the target's visible pixels and stand higher there (depth), and the
push direction runs from the target's visible centroid to the occluder's: every input of the choice is in the
image (and its segmentation), where the default reads the full silhouettes, which the camera cannot see.
``refine_radius=r`` then simulates the chosen push's direction from every start within r grid cells
and takes the one that shows the targets best (the best of the 8 neighbours uncovers twice what the image
teacher's own push does: docs/notebook/policy.md, the push landscape and the refined teacher).
``require_gain=True`` stops instead of pushing when the best simulated push would not show the targets better
than they show now (needs previews: ``lookahead > 1`` or ``refine_radius > 0``): with ``min_visible_fraction=0``
(a target is served until the perfect counter's ``min_visible_px`` line) this is the countable teacher, which never
buries a counted target for nothing (the countable reward R_c's measure: what the answer needs, not χ).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import torch
from tensordict import TensorDictBase

from mqa_rl import keys
from mqa_rl.envs import actions


ORDERS = ("least_visible", "visible_first")
GEOMETRIES = ("full", "visible")


class PrivilegedPushPolicy:
    """Oracle push policy bound to one ``SapienBinEnv`` (it reads ``env.ground_truth()``).

    Call it on the env's current tensordict: ``td = policy(td)`` writes ``action``. Not a learned
    module and not picklable into collector workers on purpose: it needs the live simulator.
    """

    def __init__(self, env, min_visible_px: int = 20, min_visible_fraction: float = 0.3,
                 max_tries_per_occluder: int = 2, finger_gap_px: float = 3.0, lookahead: int = 6,
                 order: str = "least_visible", geometry: str = "full",
                 border_px: int = 4, refine_radius: int = 0, require_gain: bool = False):
        self.env = env
        if require_gain and lookahead <= 1 and refine_radius <= 0:
            raise ValueError("require_gain=True compares simulated pushes with the present state: it needs previews "
                             "(lookahead > 1 or refine_radius > 0)")
        self.require_gain = bool(require_gain)
        if refine_radius < 0:
            raise ValueError(f"refine_radius must be >= 0 grid cells, got {refine_radius}")
        self.refine_radius = int(refine_radius)
        self.min_visible_px = min_visible_px
        self.min_visible_fraction = min_visible_fraction
        self.max_tries_per_occluder = max_tries_per_occluder
        self.finger_gap_px = finger_gap_px
        self.lookahead = lookahead
        if order not in ORDERS:
            raise ValueError(f"unknown target order {order!r}; choose one of {ORDERS}")
        self.order = order
        if geometry not in GEOMETRIES:
            raise ValueError(f"unknown oracle geometry {geometry!r}; choose one of {GEOMETRIES}")
        self.geometry, self.border_px = geometry, int(border_px)
        self._tries: dict[tuple[int, int], int] = {}
        self._episode = None

    def revealed(self, visible: np.ndarray, full: np.ndarray) -> np.ndarray:
        """Which objects count as seen: enough visible pixels and enough of their silhouette."""
        frac = np.divide(visible, full, out=np.zeros_like(visible, dtype=np.float64), where=full > 0)
        return (visible >= self.min_visible_px) & (frac >= self.min_visible_fraction)

    def choose(self) -> int:
        """The action for the env's current state (a push index or ``actions.STOP``)."""
        gt = self.env.ground_truth()
        key = (gt["question_id"], gt["scene_id"])
        if key != self._episode or int(gt["push_count"]) == 0:
            self._episode, self._tries = key, {}
        candidates = self.candidates(gt)
        if not candidates:
            return actions.STOP
        best_score = -np.inf
        if self.lookahead <= 1 or len(candidates) == 1:
            best = candidates[0]
        else:
            scores = [self.score(self.env.preview(a[0]), gt["target"]) for a in candidates[: self.lookahead]]
            best, best_score = candidates[int(np.argmax(scores))], max(scores)
        action, pair = best
        if self.refine_radius:
            action, best_score = self.refine(action, gt["target"])
        self._tries[pair] = self._tries.get(pair, 0) + 1
        if self.require_gain and best_score <= self.score(gt, gt["target"]):
            return actions.STOP
        return action

    def refine(self, action: int, target: np.ndarray) -> tuple[int, float]:
        """Of ``action`` and its direction started from the cells within ``refine_radius``, the push
        whose simulated outcome shows the targets best (the first such, ``action`` on ties), and its score."""
        d, row, col = actions.decode(action)
        r = self.refine_radius
        starts = [actions.encode(d, row + dr, col + dc) for dr in range(-r, r + 1) for dc in range(-r, r + 1)
                  if 0 <= row + dr < actions.GRID and 0 <= col + dc < actions.GRID]
        starts.sort(key=lambda a: a != action)
        scores = [self.score(self.env.preview(a), target) for a in starts]
        return starts[int(np.argmax(scores))], max(scores)

    def score(self, m: dict, target: np.ndarray) -> float:
        """How well the targets can be seen: revealed targets, then their mean visible fraction."""
        vis, full = m["visible"][target], m["full"][target]
        frac = np.clip(np.divide(vis, np.maximum(full, 1)), 0, 1)
        return float(self.revealed(vis, full).sum() + frac.mean())

    def candidates(self, gt: dict) -> list[tuple[int, tuple[int, int]]]:
        """Pushes worth trying, best guess first: for each unrevealed target (least visible first),
        each object covering it (most pixels first), pushed straight away from it and ±45°."""
        seg, masks, ids = gt["seg"], gt["masks"], gt["entity_ids"]
        targets = np.flatnonzero(gt["target"] & ~self.revealed(gt["visible"], gt["full"]))
        if self.geometry == "visible":  # only targets the image shows a part of (one it lacks has no border)
            targets = targets[gt["visible"][targets] > 0]
        seen_frac = gt["visible"][targets] / np.maximum(gt["full"][targets], 1)
        if self.order == "least_visible":
            order = targets[np.argsort(seen_frac)]
        else:                   # partly visible targets first, the most visible first: what an image shows
            order = targets[np.argsort(np.where(gt["visible"][targets] > 0, -seen_frac, 1.0), kind="stable")]
        out, seen = [], set()
        for t in order:
            counts = self._occluders(gt, t)
            target_shape = masks[t] if self.geometry == "full" else seg == ids[t]
            for j in sorted((j for j, n in counts.items() if n > 0), key=lambda j: -counts[j]):
                if self._tries.get((int(t), j), 0) >= self.max_tries_per_occluder:
                    continue
                occluder_visible = seg == ids[j]
                occluder_shape = masks[j] if self.geometry == "full" else occluder_visible
                for turn in (0, 1, -1):
                    a = self._push_away(target_shape, occluder_visible, occluder_shape, seg.shape, turn)
                    if a not in seen:
                        seen.add(a)
                        out.append((a, (int(t), j)))
        return out

    def _occluders(self, gt: dict, t: int) -> dict[int, int]:
        """{object: pixels} covering target ``t``: of its full silhouette (``full``), or, seen in the
        image (``visible``), visible pixels within ``border_px`` of the target's that stand higher than it."""
        seg, ids = gt["seg"], gt["entity_ids"]
        if self.geometry == "full":
            covered = seg[gt["masks"][t]]
            return {j: int((covered == ids[j]).sum()) for j in range(len(ids)) if j != t}
        mine = seg == ids[t]
        kernel = np.ones((2 * self.border_px + 1,) * 2, np.uint8)
        ring = cv2.dilate(mine.astype(np.uint8), kernel).astype(bool) & ~mine
        depth = gt["depth"]
        out = {}
        for j in np.unique(seg[ring]):
            k = np.flatnonzero(ids == j)
            if len(k) == 0 or k[0] == t:
                continue
            theirs = ring & (seg == j)
            near_me = mine & cv2.dilate(theirs.astype(np.uint8), kernel).astype(bool)
            if near_me.any() and np.median(depth[theirs]) < np.median(depth[near_me]):   # it stands higher
                out[int(k[0])] = int(theirs.sum())
        return out

    def _push_away(self, target_mask: np.ndarray, occluder_visible: np.ndarray, occluder_full: np.ndarray,
                   shape: tuple[int, int], turn: int = 0) -> int:
        h, w = shape
        c_t = _centroid(target_mask)
        c_o = _centroid(occluder_full)
        v = c_o - c_t
        if np.linalg.norm(v) < 2.0:                 # occluder centred on the target: push it outwards
            v = c_o - np.array([w / 2, h / 2])
        if np.linalg.norm(v) < 1e-6:
            v = np.array([1.0, 0.0])
        # image (u right, v down); direction d = d·45°, counter-clockwise as seen in the image
        d = (int(round(math.degrees(math.atan2(-v[1], v[0])) / 45.0)) + turn) % actions.DIRECTIONS
        theta = math.radians(45.0 * d)
        unit = np.array([math.cos(theta), -math.sin(theta)])
        rows, cols = np.nonzero(occluder_visible)
        pts = np.stack([cols + 0.5, rows + 0.5], axis=1)
        trailing = float(((pts - c_o) @ unit).min())
        start = c_o + (trailing - self.finger_gap_px) * unit
        col = int(np.clip(start[0] * actions.GRID / w, 0, actions.GRID - 1))
        row = int(np.clip(start[1] * actions.GRID / h, 0, actions.GRID - 1))
        return actions.encode(d, row, col)

    def __call__(self, tensordict: TensorDictBase) -> TensorDictBase:
        tensordict.set(keys.ACTION, torch.tensor(self.choose(), dtype=torch.int64))
        return tensordict


def _centroid(mask: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    return np.array([cols.mean() + 0.5, rows.mean() + 0.5])
