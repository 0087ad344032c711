"""The dashboards as a user looks at them: a tiny recipes/train_dqn.py run logging to TensorBoard, MLflow and wandb
(offline) at once, evaluated by recipes/evaluate_policy.py; TensorBoard and MLflow's UI each started on a free port of
127.0.0.1 as docs/dashboards.md says, opened in Debian's headless Chromium, where the run, a scalar curve and the Q-map
image are found, and the evaluation beside them; each server stopped after. wandb has no local dashboard: its offline
run is checked on disk (``wandb sync`` shows it on a wandb server). In the slow lane: a killed run resumed shows each
step once on TensorBoard and in the MLflow store, as its CSV has it.

Never skipped: a missing browser fails with the command that installs it (tools/test.sh runs it)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest
from dashboard_pages import MLflowPage, TensorBoardPage, serving

from conftest import REPO
from mqa_rl.demo.page_driver import BrowserMissing, chromium

ENV = {**os.environ, "PYTHONPATH": str(REPO), "WANDB_MODE": "offline", "WANDB_SILENT": "true"}


def _run(*args, cwd):
    out = subprocess.run([sys.executable, *args], cwd=cwd, capture_output=True, text=True, timeout=600, env=ENV)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def run(small_dataset_dir, tmp_path_factory):
    """``<root>/runs/dqn``: 32 frames with an evaluation at 32, then greedy and random evaluated on it."""
    root = tmp_path_factory.mktemp("dashboards")
    run = root / "runs" / "dqn"
    _run(str(REPO / "recipes" / "train_dqn.py"), "profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={run}",
         "threads=1", "logger=[tensorboard,mlflow,wandb]", cwd=root)
    _run(str(REPO / "recipes" / "evaluate_policy.py"), f"run={run}", "episodes_per_level=1", "difficulties=[easy]",
         "policies=[greedy,random]", "video_episodes=1", "video_format=gif", f"out_dir={root / 'eval'}", cwd=root)
    return run


def open_browser():
    try:
        return chromium(width=1400, height=1300)
    except BrowserMissing as error:
        pytest.fail(str(error))


def last_value(run: Path, name: str) -> float:
    return float((run / "csv" / "scalars" / f"{name}.csv").read_text().split()[-1].split(",")[1])


def port_closed(url: str) -> bool:
    host, port = url.removeprefix("http://").rstrip("/").split(":")
    with socket.socket() as s:
        return s.connect_ex((host, int(port))) != 0


@pytest.mark.timeout(900)
def test_tensorboard_shows_the_run_its_curves_q_map_and_evaluation(run, tmp_path):
    with serving("tensorboard", run.parent) as url:
        driver = open_browser()
        try:
            page = TensorBoardPage(driver, url)
            assert page.open() == ["dqn/tensorboard"]
            page.show("^(train/loss|eval/qmap|policy_eval/easy/greedy/pushes|policy_eval/easy_0)$")
            card = page.scalar_card("train/loss")
            assert "dqn/tensorboard" in card and f"{last_value(run, 'train/loss'):.3g}"[:4] in card   # the last value
            assert "dqn/tensorboard" in page.scalar_card("policy_eval/easy/greedy/pushes")   # the evaluation, at 32
            assert page.image("eval/qmap").size["width"] > 100
            page.image("policy_eval/easy_0")                                    # its episode's video (a GIF)
            assert page.screenshot(tmp_path / "tensorboard.png").stat().st_size > 10_000
        finally:
            driver.quit()
    assert port_closed(url)


@pytest.mark.timeout(900)
def test_mlflow_ui_shows_the_run_its_curves_q_map_and_evaluation(run, tmp_path):
    import mlflow

    saved = json.loads((run / "mlflow_run.json").read_text())
    experiment = mlflow.MlflowClient(saved["tracking_uri"]).get_run(saved["run_id"]).info.experiment_id
    with serving("mlflow", run / "mlflow.db") as url:
        driver = open_browser()
        try:
            page = MLflowPage(driver, url)
            page.open_run(experiment, saved["run_id"], str(run))
            assert f"{run} (train/loss)" in page.chart("train/loss")
            assert f"{run} (policy_eval/easy/greedy/pushes)" in page.chart("policy_eval/easy/greedy/pushes")
            assert page.image("eval/qmap").size["width"] > 50
            assert page.screenshot(tmp_path / "mlflow.png").stat().st_size > 10_000
            listed = page.artifacts(experiment, saved["run_id"])
            assert {"images", "eval", "policy_eval"} <= set(listed)           # Q-maps, episode videos, the results table
        finally:
            driver.quit()
    assert port_closed(url)


def test_the_offline_wandb_run_holds_the_run_and_its_evaluation(run):
    run_id = (run / "wandb_run_id").read_text().strip()
    offline = sorted((run / "wandb").glob(f"offline-run-*-{run_id}"))
    assert len(offline) == 2                                    # the training, then its evaluation: one wandb run
    assert list((offline[0] / "files" / "media" / "images" / "eval").glob("qmap_*.png"))
    assert list((offline[1] / "files" / "media" / "videos" / "policy_eval").glob("easy_0_*.gif"))


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_a_killed_run_resumed_shows_each_step_once_as_the_csv_has_it(small_dataset_dir, tmp_path):
    """SIGKILL after 56 frames (the checkpoint at 32), then resume=true: TensorBoard serves the CSV's rows, each step
    once; the MLflow store holds one run, each step once."""
    run = tmp_path / "runs" / "r"
    args = [str(REPO / "recipes" / "train_dqn.py"), "profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={run}",
            "threads=1", "logger=[tensorboard,mlflow]", "collector.total_frames=96", "collector.annealing_frames=96",
            "checkpoint.interval_frames=32"]
    first = subprocess.Popen([sys.executable, *args], cwd=tmp_path, env=ENV, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    epsilon = run / "csv" / "scalars" / "train" / "epsilon.csv"
    deadline = time.time() + 600
    while not (epsilon.exists() and int(epsilon.read_text().split()[-1].split(",")[0]) >= 56):
        assert first.poll() is None and time.time() < deadline, "the run ended before 56 frames"
        time.sleep(0.2)
    first.send_signal(signal.SIGKILL)
    first.wait()
    assert "resumed from" in _run(*args, "resume=true", cwd=tmp_path).stdout

    def csv_rows(name):
        return [(int(s), round(float(v), 5)) for s, v in (line.split(",") for line in
                                                          (run / "csv" / "scalars" / f"{name}.csv").read_text().split())]
    with serving("tensorboard", run.parent) as url:
        for name in ("train/epsilon", "train/loss", "eval/reward"):
            with urllib.request.urlopen(f"{url}data/plugin/scalars/scalars?run=r/tensorboard&tag={name}") as answer:
                served = [(step, round(value, 5)) for _, step, value in json.load(answer)]
            assert served == csv_rows(name) and served[-1][0] == 96, name
    import mlflow

    saved = json.loads((run / "mlflow_run.json").read_text())
    client = mlflow.MlflowClient(saved["tracking_uri"])
    steps = [m.step for m in client.get_metric_history(saved["run_id"], "train/epsilon")]
    assert steps == list(range(8, 97, 8))
    assert len(client.search_runs([client.get_run(saved["run_id"]).info.experiment_id])) == 1
