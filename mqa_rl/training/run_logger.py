"""``RunLogger``: a run's metrics, images, videos and texts, written as files (CSV scalars, media) and to the
dashboards its ``logger`` settings choose (TensorBoard, MLflow, wandb: ``mqa_rl.training.dashboards``).

CSV scalars land in ``<out_dir>/csv/scalars/<group>/<name>.csv`` (rows ``step,value``, step = collected
frames) whatever the dashboards; ``recipes/evaluate_policy.py plot=`` reads them. Images are also written to
``<out_dir>/media``. On resume, rows logged after the checkpoint are dropped first (``trim_scalars``), so no step is
logged twice. An evaluation of a run logs into the run's own dashboards (``RunLogger.of_run``), leaving its files alone.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Mapping

import cv2
import numpy as np
import torch
from omegaconf import OmegaConf
from torchrl.record.loggers import CSVLogger

from mqa_rl.envs.video import read_video
from mqa_rl.files import write_atomic
from mqa_rl.training.dashboards import held_steps, open_dashboards

VIDEO_FPS = 2


def trim_scalars(csv_dir: str | Path, max_step: int, exclude: str | None = None) -> int:
    """Drop rows with step > ``max_step`` from every scalar CSV (atomically), except under folders
    named ``exclude`` (series counted in other steps); returns rows dropped."""
    dropped = 0
    for path in Path(csv_dir).rglob("*.csv"):
        if exclude is not None and exclude in path.relative_to(csv_dir).parts[:-1]:
            continue
        lines = path.read_text().splitlines()
        keep = [ln for ln in lines if ln and float(ln.split(",", 1)[0]) <= max_step]
        if len(keep) != len(lines):
            dropped += len(lines) - len(keep)
            write_atomic(path, "".join(f"{ln}\n" for ln in keep))
    return dropped


class RunLogger:
    """``settings``: the ``logger`` config group's values (tensorboard, mlflow, wandb, project, ...), as a mapping
    and/or keywords; ``files=False``: the dashboards alone (an evaluation of the run, see ``of_run``)."""

    def __init__(self, out_dir: str | Path, settings: Mapping[str, Any] | None = None, *, exp_name: str,
                 config: dict | None = None, files: bool = True, **more_settings):
        self.out_dir = Path(out_dir)
        self.csv = CSVLogger("csv", log_dir=str(self.out_dir)) if files else None
        self.media = self.out_dir / "media"
        if files:
            self.media.mkdir(parents=True, exist_ok=True)
        self.dashboards = open_dashboards(self.out_dir, {**(settings or {}), **more_settings}, exp_name=exp_name,
                                          config=config)
        self.held = held_steps(self.dashboards["mlflow"]) if "mlflow" in self.dashboards else {}
        if self.csv is not None and config is not None:
            self.csv.log_hparams(config)

    @classmethod
    def of_run(cls, run: str | Path) -> "RunLogger":
        """The dashboards of a training run (as its ``config.yaml`` chose them), for an evaluation of it."""
        settings = OmegaConf.to_container(OmegaConf.load(Path(run) / "config.yaml")).get("logger") or {}
        return cls(run, settings, exp_name=Path(run).name, files=False)

    def __enter__(self) -> "RunLogger":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def log_metrics(self, metrics: dict[str, float], step: int) -> None:
        finite = {k: float(v) for k, v in metrics.items() if v is not None and np.isfinite(v)}
        if self.csv is not None:
            for k, v in finite.items():
                self.csv.log_scalar(k, v, step=step)
        for name, dashboard in self.dashboards.items():
            new = {k: v for k, v in finite.items() if step > self.held.get(k, -1)} if name == "mlflow" else finite
            if new:
                dashboard.log_metrics(new, step=step)

    def log_image(self, name: str, image: np.ndarray, step: int) -> Path | None:
        """An RGB image: a PNG in ``media`` (with files) and on every dashboard."""
        path = None
        if self.csv is not None:
            path = self.media / f"{name.replace('/', '_')}_{step:07d}.png"
            ok, png = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
            if not ok:
                raise OSError(f"OpenCV cannot encode {name} (step {step}) as PNG")
            write_atomic(path, png.tobytes())
        for kind, dashboard in self.dashboards.items():
            if kind == "tensorboard":
                dashboard.experiment.add_image(name, image, step, dataformats="HWC")
            elif kind == "mlflow":
                import mlflow

                mlflow.log_image(image, key=name, step=step)
            else:
                import wandb

                dashboard.experiment.log({name: wandb.Image(image)})
        return path

    def log_figure(self, name: str, path: str | Path, step: int) -> None:
        """A figure file (PNG) on every dashboard."""
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if image is None:
            raise OSError(f"OpenCV cannot read the figure {path}")
        self.log_image(name, cv2.cvtColor(image, cv2.COLOR_BGR2RGB), step)

    def log_video_file(self, name: str, path: Path, step: int) -> None:
        """A video written by ``mqa_rl.envs.video.write_video``, on every dashboard (the file stays where it is)."""
        for kind, dashboard in self.dashboards.items():
            try:
                if kind == "tensorboard":
                    video = torch.from_numpy(np.stack(read_video(path))).permute(0, 3, 1, 2)[None]
                    dashboard.log_video(name, video, step=step, fps=VIDEO_FPS)
                elif kind == "mlflow":
                    import mlflow

                    mlflow.log_artifact(str(path), f"{name}/{step:07d}")
                else:
                    import wandb

                    dashboard.experiment.log({name: wandb.Video(str(path))})
            except Exception as error:  # video support needs optional packages (moviepy); the file stays
                warnings.warn(f"{kind} could not log video {path}: {error}", stacklevel=2)

    def log_text(self, name: str, markdown: str, step: int) -> None:
        """A table or report (markdown) on every dashboard."""
        for kind, dashboard in self.dashboards.items():
            if kind == "tensorboard":
                dashboard.experiment.add_text(name, markdown, step)
            elif kind == "mlflow":
                import mlflow

                mlflow.log_text(markdown, f"{name}/{step:07d}.md")
            else:
                dashboard.log_str(name, markdown, step=step)

    def close(self) -> None:
        for kind, dashboard in self.dashboards.items():
            if kind == "mlflow":
                import mlflow

                mlflow.end_run()
            else:
                dashboard.close()
        self.dashboards = {}
