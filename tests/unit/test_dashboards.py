"""The dashboards read back: what RunLogger logs to TensorBoard's event files and to an MLflow store is what their
readers find (scalars, images, videos, texts, hyper-parameters), the CSV files beside them unchanged; a resumed run
continues the same MLflow run without logging a step twice; the logger group composes and bad settings say what to do."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from conftest import compose_recipe_config
from mqa_rl.envs.video import write_video
from mqa_rl.training.run_logger import RunLogger

CONFIG = {"reward": {"name": "global", "beta_final": 0.5}, "model": {"channels": [16, 32]}, "demos": {"path": None}}
# values a float32 holds exactly (TensorBoard's scalars are float32)
METRICS = {8: {"train/loss": 0.5, "train/epsilon": 0.875}, 16: {"train/loss": 0.25, "train/epsilon": 0.625,
                                                                 "eval/reward": float("nan")}}
IMAGE = np.random.default_rng(0).integers(0, 255, (40, 56, 3), dtype=np.uint8)


def _log(logger: RunLogger, tmp_path, metrics=METRICS) -> None:
    for step, values in metrics.items():
        logger.log_metrics(values, step=step)
    logger.log_image("eval/qmap", IMAGE, 16)
    logger.log_video_file("eval/video_0", write_video([IMAGE] * 3, tmp_path / "episode.gif"), 16)
    logger.log_text("policy_eval/results", "| policy | reward |\n|---|---|\n| greedy | +0.5 |", 16)


def _csv(run, name):
    with open(run / "csv" / "scalars" / f"{name}.csv") as f:
        return [(int(s), float(v)) for s, v in csv.reader(f)]


def test_tensorboard_event_files_hold_what_was_logged(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    from tensorboard.backend.event_processing.plugin_event_accumulator import EventAccumulator as PluginAccumulator

    run = tmp_path / "run"
    with RunLogger(run, {"tensorboard": True}, exp_name="dqn", config=CONFIG) as logger:
        _log(logger, tmp_path)
    events = EventAccumulator(str(run / "tensorboard"), size_guidance={"images": 0, "scalars": 0})
    events.Reload()
    for name in ("train/loss", "train/epsilon"):
        read = [(e.step, e.value) for e in events.Scalars(name)]
        assert read == [(s, m[name]) for s, m in METRICS.items() if name in m]
        assert _csv(run, name) == read                                   # the CSV beside them: the same rows
    assert "eval/reward" not in events.Tags()["scalars"]                  # NaN is left out, as in the CSV
    (image,) = events.Images("eval/qmap")
    assert (image.step, image.width, image.height) == (16, 56, 40)
    (video,) = events.Images("eval/video_0")                               # an animated GIF (TensorBoard's video)
    assert video.encoded_image_string.startswith(b"GIF8")
    plugins = PluginAccumulator(str(run / "tensorboard"))
    plugins.Reload()
    (text,) = plugins.Tensors("policy_eval/results/text_summary")       # torch's add_text names the tag so
    assert (text.step, text.tensor_proto.string_val[0].decode()) == (16, "| policy | reward |\n|---|---|\n| greedy | +0.5 |")
    assert "_hparams_/session_start_info" in plugins.PluginTagToContent("hparams")
    assert (run / "media" / "eval_qmap_0000016.png").exists()


def test_mlflow_store_holds_what_was_logged_and_a_resumed_run_continues_it(tmp_path):
    import mlflow

    run = tmp_path / "run"
    settings = {"mlflow": True, "project": "mqa_rl"}
    with RunLogger(run, settings, exp_name="dqn", config=CONFIG) as logger:
        _log(logger, tmp_path)
    saved = json.loads((run / "mlflow_run.json").read_text())
    assert saved["tracking_uri"] == f"sqlite:///{(run / 'mlflow.db').resolve()}"
    client = mlflow.MlflowClient(saved["tracking_uri"])
    history = lambda name: [(m.step, m.value) for m in client.get_metric_history(saved["run_id"], name)]  # noqa: E731
    assert history("train/loss") == [(8, 0.5), (16, 0.25)] and history("train/epsilon") == [(8, 0.875), (16, 0.625)]
    assert _csv(run, "train/loss") == history("train/loss") and not history("eval/reward")
    got = client.get_run(saved["run_id"])
    assert got.info.run_name == str(run) and got.data.params == {
        "reward.name": "global", "reward.beta_final": "0.5", "model.channels": "[16, 32]"}
    artifacts = {a.path for a in client.list_artifacts(saved["run_id"])}
    assert {"images", "eval", "policy_eval"} <= artifacts
    assert any("qmap" in a.path for a in client.list_artifacts(saved["run_id"], "images"))
    # resumed from a checkpoint at step 8: steps 8 and 16 come again, the store keeps one point per step
    with RunLogger(run, settings, exp_name="dqn", config={**CONFIG, "collector": {"total_frames": 24}}) as logger:
        for step, loss in ((16, 0.2), (24, 0.1)):
            logger.log_metrics({"train/loss": loss}, step=step)
    assert json.loads((run / "mlflow_run.json").read_text()) == saved
    assert history("train/loss") == [(8, 0.5), (16, 0.25), (24, 0.1)]
    assert len(client.search_runs([got.info.experiment_id])) == 1


def test_bad_logger_settings_say_what_to_do(tmp_path):
    with pytest.raises(ValueError, match=r"logger.tensorboard='yes' must be true or false.*logger=\[tensorboard,mlflow\]"):
        RunLogger(tmp_path / "a", {"tensorboard": "yes"}, exp_name="dqn")
    with pytest.raises(ValueError, match="no tracking URI: give sqlite:///<path>.db"):
        RunLogger(tmp_path / "b", {"mlflow": True, "mlflow_uri": "runs/mlflow.db"}, exp_name="dqn")


@pytest.mark.parametrize("overrides, on", [
    ([], ["tensorboard"]),
    (["logger=[tensorboard,wandb]"], ["tensorboard", "wandb"]),
    (["logger=mlflow"], ["mlflow"]),
    (["logger=csv"], []),
    (["profile=smoke"], []),                                   # the tests' profile: CSV alone
    (["profile=smoke", "logger=[tensorboard,mlflow]"], ["tensorboard", "mlflow"]),
])
def test_the_logger_group_chooses_the_dashboards(overrides, on):
    from mqa_rl.training.dashboards import chosen

    cfg = compose_recipe_config("train_dqn", overrides)
    assert chosen(cfg.logger) == on and "progress" in cfg.logger and cfg.logger.project == "mqa_rl"


def test_a_run_that_logged_to_wandb_resumes_under_the_new_logger_group():
    from omegaconf import OmegaConf

    from mqa_rl.training.resume_guard import config_changes

    new = OmegaConf.to_container(compose_recipe_config("train_dqn", []), resolve=False)
    old = {**new, "logger": {"wandb": True, "project": "mqa_rl", "progress": True}}
    assert config_changes(old, new) == []
