"""Q maps drawn over the camera image: where the policy wants to push, for people to inspect.

``qmap_image`` colours each grid cell by its best push Q value (max over the 8 directions; masked
cells stay uncoloured), marks the greedy push with an arrow and prints Q(stop). ``qmap_episode_frames``
puts it beside the episode frame of every step of a greedy rollout (one that stored ``action_value``).
"""

from __future__ import annotations

import cv2
import numpy as np
import torch

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.video import episode_frames


def qmap_image(rgb: np.ndarray, action_value: torch.Tensor, action_mask: torch.Tensor | None = None,
               scale: int = 2, alpha: float = 0.55) -> np.ndarray:
    """RGB [H, W, 3] uint8 and Q [6273] → an upscaled RGB image with the Q heat map and greedy push."""
    q = action_value.detach().to(torch.float32).clone()
    allowed = torch.ones_like(q, dtype=torch.bool) if action_mask is None else action_mask.bool()
    q[~allowed] = float("nan")
    push = q[: actions.NUM_PUSHES].view(actions.DIRECTIONS, actions.GRID, actions.GRID)
    valid = ~torch.isnan(push).all(0)
    best = torch.where(valid, torch.nan_to_num(push, nan=-torch.inf).amax(0), torch.zeros(()))
    lo, hi = (best[valid].min().item(), best[valid].max().item()) if valid.any() else (0.0, 1.0)
    norm = ((best - lo) / max(hi - lo, 1e-9)).clamp(0, 1).numpy()
    h, w = rgb.shape[:2]
    heat = cv2.applyColorMap((norm * 255).astype(np.uint8), cv2.COLORMAP_JET)[..., ::-1]
    heat = cv2.resize(heat, (w * scale, h * scale), interpolation=cv2.INTER_NEAREST)
    cells = cv2.resize(valid.numpy().astype(np.uint8), (w * scale, h * scale), interpolation=cv2.INTER_NEAREST).astype(bool)
    img = cv2.resize(np.ascontiguousarray(rgb), (w * scale, h * scale), interpolation=cv2.INTER_NEAREST)
    img[cells] = (alpha * heat[cells] + (1 - alpha) * img[cells]).astype(np.uint8)
    greedy = int(torch.nan_to_num(q, nan=-torch.inf).argmax())
    stop_q = q[actions.STOP].item()
    if greedy != actions.STOP:
        d, row, col = actions.decode(greedy)
        u, v = actions.cell_centre_uv(row, col, h, w) * scale
        du, dv = actions.direction_xy(d) * (w * scale / 8)
        cv2.arrowedLine(img, (int(u), int(v)), (int(u + du), int(v - dv)), (255, 255, 255), 2, cv2.LINE_AA, tipLength=0.3)
    label = f"Q push max {hi:+.2f} min {lo:+.2f}  stop {stop_q:+.2f}" + ("  -> STOP" if greedy == actions.STOP else "")
    cv2.putText(img, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def qmap_episode_frames(rollout, camera, question: str = "", scale: int = 2) -> list[np.ndarray]:
    """Episode frames (push arrows) with the Q map of each step beside them; the last frame unchanged."""
    frames = episode_frames(rollout, camera, question, scale)
    size = rollout[keys.RGB].shape[-1] * scale
    out = []
    for t, frame in enumerate(frames):
        if t < rollout.shape[0]:
            rgb = rollout[keys.RGB][t].numpy().transpose(1, 2, 0)
            qimg = qmap_image(rgb, rollout[keys.ACTION_VALUE][t], rollout[keys.ACTION_MASK][t], scale)
        else:                                      # final state: no decision taken there
            qimg = np.zeros((size, size, 3), np.uint8)
        pad = np.full((frame.shape[0] - qimg.shape[0], qimg.shape[1], 3), 255, np.uint8)
        out.append(np.concatenate([frame, np.concatenate([pad, qimg], 0)], 1))
    return out
