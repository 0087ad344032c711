"""The dashboards a run logs to beside its CSV files: TorchRL's own loggers (``torchrl.record.loggers``), chosen by
the ``logger`` config group (``logger=tensorboard | mlflow | wandb | csv``; several at once: ``logger=[tensorboard,mlflow]``).

One dashboard run per run folder, continued when the run resumes (and by the evaluations of the run):

- TensorBoard: event files in ``<out_dir>/tensorboard``; look with ``tensorboard --logdir runs/ --host 127.0.0.1``.
  Steps logged again after a resume replace the ones logged past the checkpoint (TensorBoard drops a tag's points
  from a step logged anew, as the CSV trim does).
- MLflow: a SQLite store (``logger.mlflow_uri``; null: ``<out_dir>/mlflow.db``, artifacts beside it); the run's id in
  ``<out_dir>/mlflow_run.json``. MLflow cannot take a point back: after a resume, the steps it holds are not logged
  again (``held_steps``).
- wandb: offline in ``<out_dir>/wandb`` (``wandb sync`` it to a server), the run's id in ``<out_dir>/wandb_run_id``.
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import Any, Mapping

from mqa_rl.files import write_atomic
from mqa_rl.training.resume_guard import flatten

DASHBOARDS = ("tensorboard", "mlflow", "wandb")
MLFLOW_RUN = "mlflow_run.json"
WANDB_RUN = "wandb_run_id"


def chosen(settings: Mapping[str, Any]) -> list[str]:
    """The dashboards ``settings`` (the ``logger`` group's values) turn on; a flag that is no boolean is refused."""
    for name in DASHBOARDS:
        if not isinstance(settings.get(name, False), bool):
            raise ValueError(f"logger.{name}={settings[name]!r} must be true or false; choose dashboards with the group, "
                             f"e.g. logger=tensorboard or logger=[tensorboard,mlflow] (logger=csv: none)")
    return [name for name in DASHBOARDS if settings.get(name, False)]


def hparams(config: Mapping[str, Any]) -> dict[str, Any]:
    """The config as flat ``{"a.b": value}`` of the types dashboards take (lists as text, nulls left out)."""
    return {k: v if isinstance(v, (bool, int, float, str)) else str(v) for k, v in flatten(config).items() if v is not None}


def mlflow_uri(out_dir: Path, settings: Mapping[str, Any]) -> str:
    """``logger.mlflow_uri`` (a relative SQLite path made absolute: the run's evaluations open it from anywhere),
    or a SQLite store in the run folder."""
    uri = settings.get("mlflow_uri") or f"sqlite:///{(out_dir / 'mlflow.db').resolve()}"
    if "://" not in str(uri):
        raise ValueError(f"logger.mlflow_uri={uri!r} is no tracking URI: give sqlite:///<path>.db (a local store), "
                         f"http://<host>:<port> (an MLflow server), or null (<out_dir>/mlflow.db)")
    if uri.startswith("sqlite:///") and not uri.startswith("sqlite:////"):
        uri = f"sqlite:///{Path(uri.removeprefix('sqlite:///')).resolve()}"
    return uri


def open_tensorboard(out_dir: Path, config: Mapping[str, Any] | None):
    from torch.utils.tensorboard.summary import hparams as hparams_summary
    from torchrl.record.loggers import TensorboardLogger

    logger = TensorboardLogger("tensorboard", log_dir=str(out_dir))
    if config is not None:       # the run's own hparams (TorchRL's log_hparams would make a second run beside it)
        logger.experiment.file_writer.add_summary(hparams_summary(hparams(config), {})[1])
    return logger


def open_mlflow(out_dir: Path, settings: Mapping[str, Any], config: Mapping[str, Any] | None):
    from torchrl.record.loggers import MLFlowLogger
    import mlflow

    uri = mlflow_uri(out_dir, settings)
    saved = json.loads((out_dir / MLFLOW_RUN).read_text()) if (out_dir / MLFLOW_RUN).exists() else {}
    run_id = saved.get("run_id") if saved.get("tracking_uri") == uri else None
    if run_id:
        os.environ["MLFLOW_RUN_ID"] = run_id          # mlflow.start_run continues it
    store = Path(uri.removeprefix("sqlite:///")).parent if uri.startswith("sqlite:///") else None
    logger = MLFlowLogger(settings.get("project", "mqa_rl"), uri,
                          artifact_location=(store / "mlartifacts").as_uri() if store else None)
    if run_id is None:
        mlflow.set_tag("mlflow.runName", str(out_dir))
        write_atomic(out_dir / MLFLOW_RUN, json.dumps({"tracking_uri": uri, "run_id": logger.experiment.info.run_id}))
        if config is not None:                       # MLflow params are written once: a resumed run keeps its first
            logger.log_hparams(hparams(config))
    return logger


def open_wandb(out_dir: Path, settings: Mapping[str, Any], exp_name: str, config: Mapping[str, Any] | None):
    from torchrl.record.loggers import WandbLogger

    id_file = out_dir / WANDB_RUN
    run_id = id_file.read_text().strip() if id_file.exists() else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        logger = WandbLogger(exp_name=exp_name, offline=True, save_dir=str(out_dir), project=settings.get("project", "mqa_rl"),
                             log_env_packages=False, config=dict(config or {}), id=run_id,
                             resume="allow" if run_id else None)
    if run_id is None:
        id_file.write_text(logger.experiment.id)
    return logger


INSTALL = {"tensorboard": "pip install tensorboard 'moviepy<2'", "mlflow": "pip install 'mqa_rl[mlflow]'",
           "wandb": "pip install wandb"}


def open_dashboards(out_dir: str | Path, settings: Mapping[str, Any], *, exp_name: str,
                    config: Mapping[str, Any] | None = None) -> dict:
    """``{name: TorchRL logger}`` for the dashboards ``settings`` choose, each continuing the run folder's dashboard
    run when it has one; ``config``: the hyper-parameters to show beside the curves (None: an evaluation of the run)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    opened = {}
    for name in chosen(settings):
        try:
            opened[name] = (open_tensorboard(out_dir, config) if name == "tensorboard" else
                            open_mlflow(out_dir, settings, config) if name == "mlflow" else
                            open_wandb(out_dir, settings, exp_name, config))
        except ImportError as error:
            raise ImportError(f"logger={name} needs a package this environment lacks ({error}): {INSTALL[name]}, "
                              f"or choose another logger (logger=csv: none)") from error
    return opened


def held_steps(mlflow_logger) -> dict[str, int]:
    """The last step of every metric the MLflow run already holds (a resumed run logs past them only)."""
    import mlflow

    client, run_id = mlflow.MlflowClient(), mlflow_logger.experiment.info.run_id
    return {key: max(m.step for m in client.get_metric_history(run_id, key)) for key in client.get_run(run_id).data.metrics}
