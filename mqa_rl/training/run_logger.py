"""``RunLogger``: the training run's metrics through TorchRL's loggers (CSV always, wandb offline by
default), plus images and videos as files next to them.

CSV scalars land in ``<out_dir>/csv/scalars/<group>/<name>.csv`` (rows ``step,value``, step = collected
frames); ``recipes/plot_curves.py`` reads them. wandb runs offline under ``<out_dir>/wandb`` (sync them
later with ``wandb sync``); a resumed run continues the same wandb run id. On resume, rows logged after
the checkpoint are dropped first (``trim_scalars``), so no step is logged twice.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import cv2
import numpy as np
from torchrl.record.loggers import CSVLogger

from mqa_rl.files import write_atomic


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
    def __init__(self, out_dir: str | Path, *, wandb: bool, project: str, exp_name: str, config: dict):
        self.out_dir = Path(out_dir)
        self.csv = CSVLogger("csv", log_dir=str(self.out_dir))
        self.media = self.out_dir / "media"
        self.media.mkdir(parents=True, exist_ok=True)
        self.wandb = None
        if wandb:
            from torchrl.record.loggers import WandbLogger

            id_file = self.out_dir / "wandb_run_id"
            run_id = id_file.read_text().strip() if id_file.exists() else None
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DeprecationWarning)
                self.wandb = WandbLogger(exp_name=exp_name, offline=True, save_dir=str(self.out_dir), project=project,
                                         log_env_packages=False, config=config, id=run_id, resume="allow" if run_id else None)
            if run_id is None:
                id_file.write_text(self.wandb.experiment.id)
        self.csv.log_hparams(config)

    def log_metrics(self, metrics: dict[str, float], step: int) -> None:
        finite = {k: float(v) for k, v in metrics.items() if v is not None and np.isfinite(v)}
        for k, v in finite.items():
            self.csv.log_scalar(k, v, step=step)
        if self.wandb is not None and finite:
            self.wandb.log_metrics(finite, step=step)

    def log_image(self, name: str, image: np.ndarray, step: int) -> Path:
        path = self.media / f"{name.replace('/', '_')}_{step:07d}.png"
        ok, png = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        if not ok:
            raise OSError(f"OpenCV cannot encode {name} (step {step}) as PNG")
        write_atomic(path, png.tobytes())
        if self.wandb is not None:
            import wandb

            self.wandb.experiment.log({name: wandb.Image(image)})
        return path

    def log_video_file(self, name: str, path: Path, step: int) -> None:
        if self.wandb is not None:
            import wandb

            try:
                self.wandb.experiment.log({name: wandb.Video(str(path))})
            except Exception as error:  # wandb's video support needs optional packages; the file stays
                warnings.warn(f"wandb could not log video {path}: {error}", stacklevel=2)

    def close(self) -> None:
        if self.wandb is not None:
            self.wandb.experiment.finish()
