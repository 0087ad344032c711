"""Episode videos for people to look at: the top camera frames, each push drawn as an arrow.

``episode_frames`` turns a rollout (a tensordict of shape [T] from ``env.rollout``) into annotated
frames; ``write_video`` writes mp4 (``.mp4``), WebM (``.webm``, VP8: what browsers play, OpenCV's
mp4 codec is not) or animated gif (``.gif``) with OpenCV, atomically; ``read_video`` reads one back (for a dashboard).
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from mqa_rl import keys
from mqa_rl.sim.geometry import CameraSpec

ARROW = (255, 40, 40)      # RGB


def annotate(rgb: np.ndarray, scale: int, lines: list[str]) -> np.ndarray:
    """The image upscaled ``scale`` times under a white banner with one text line per entry of ``lines``."""
    img = cv2.resize(rgb, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    banner = np.full((18 * len(lines) + 6, img.shape[1], 3), 255, np.uint8)
    for i, text in enumerate(lines):
        cv2.putText(banner, text, (6, 16 + 18 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([banner, img], axis=0)


def draw_push(rgb: np.ndarray, start: np.ndarray, end: np.ndarray, camera: CameraSpec, scale: int = 1) -> np.ndarray:
    """Draw the push from world ``start`` to ``end`` as an arrow on an (upscaled) RGB image."""
    (p0, p1), _ = camera.project(np.stack([start, end]))
    img = np.ascontiguousarray(rgb)
    a = tuple(int(round(x * scale)) for x in p0)
    b = tuple(int(round(x * scale)) for x in p1)
    cv2.arrowedLine(img, a, b, ARROW, max(1, scale), cv2.LINE_AA, tipLength=0.25)
    cv2.circle(img, a, max(2, 2 * scale), ARROW, -1, cv2.LINE_AA)
    return img


def episode_frames(rollout, camera: CameraSpec, question: str = "", scale: int = 2) -> list[np.ndarray]:
    """Frame t shows state t with the push taken from it; a final frame shows the last state."""
    rgb = rollout[keys.RGB].numpy().transpose(0, 2, 3, 1)
    nxt = rollout["next"]
    frames = []
    for t in range(rollout.shape[0]):
        stop = bool(nxt[keys.IS_STOP][t].item())
        label = "stop" if stop else f"push {t + 1}"
        img = annotate(rgb[t], scale, [question, f"step {t}: {label}"])
        if not stop:
            body = img[img.shape[0] - rgb.shape[1] * scale:]
            body[:] = draw_push(body, nxt[keys.PUSH_START][t].numpy(), nxt[keys.PUSH_END][t].numpy(), camera, scale)
        frames.append(img)
    last = nxt[keys.RGB][-1].numpy().transpose(1, 2, 0)
    frames.append(annotate(np.ascontiguousarray(last), scale, [question, f"step {rollout.shape[0]}: final"]))
    return frames


def write_video(frames: list[np.ndarray], path, fps: float = 1.5) -> Path:
    """Write RGB frames to ``path`` (.mp4 or .gif); the file appears only once complete."""
    path = Path(path)
    if not frames:
        raise ValueError("no frames to write")
    suffix = path.suffix.lower()
    if suffix not in (".mp4", ".webm", ".gif"):
        raise ValueError(f"unsupported video format {suffix!r}; use .mp4 or .gif, or .webm (VP8) for browsers")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{suffix}")
    bgr = [cv2.cvtColor(f, cv2.COLOR_RGB2BGR) for f in frames]
    try:
        if suffix in (".mp4", ".webm"):
            h, w = bgr[0].shape[:2]
            fourcc = "mp4v" if suffix == ".mp4" else "VP80"
            writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h))
            if not writer.isOpened():
                raise RuntimeError(f"OpenCV cannot write {suffix} here; write a .gif instead")
            for f in bgr:
                writer.write(f)
            writer.release()
        else:
            anim = cv2.Animation()
            anim.frames = bgr
            anim.durations = [int(1000 / fps)] * len(bgr)
            ok = cv2.imwriteanimation(str(tmp), anim)
            if not ok:
                raise RuntimeError(f"OpenCV failed to write {path}")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def read_video(path) -> list[np.ndarray]:
    """The RGB frames of a video written by ``write_video`` (.mp4, .webm or .gif)."""
    path = Path(path)
    if path.suffix.lower() == ".gif":
        ok, anim = cv2.imreadanimation(str(path))
        frames = list(anim.frames) if ok else []
    else:
        capture, frames = cv2.VideoCapture(str(path)), []
        while (read := capture.read())[0]:
            frames.append(read[1])
        capture.release()
    if not frames:
        raise ValueError(f"OpenCV read no frame from {path}")
    return [cv2.cvtColor(f[..., :3], cv2.COLOR_BGR2RGB) for f in frames]
