"""The three Ray backends on the two-node cluster against the local ones: rollouts bit-identical and complete
after a worker is killed mid-collection, evaluate_policy.py's episodes identical, and a short DQN training
through TorchRL's RayCollector that learns as the local one does and resumes."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time

import pytest
import torch

from mqa_rl import keys
from mqa_rl.collectors.rollouts import collect_rollouts
from mqa_rl.collectors.store import load_records
from mqa_rl.files import load_tensors
from conftest import compose_recipe_config, load_recipe

pytestmark = pytest.mark.ray

PLAN = dict(policy={"kind": "random"}, split="train", question_types=["counting", "existence"], max_per_group=2,
            repeats=2, max_pushes=3, chunk_episodes=1, progress=False, store_depth=False)


def by_slot(root):
    records = load_records(root)
    return records[records[keys.SLOT].argsort()]


def assert_same_records(a, b):
    assert a.shape == b.shape
    for key in a.keys(True, True):
        x, y = a.get(key), b.get(key)
        same = torch.equal(torch.nan_to_num(x), torch.nan_to_num(y)) if x.is_floating_point() else torch.equal(x, y)
        assert same, key


def worker_pids() -> list[int]:
    out = subprocess.run(["pgrep", "-f", "ray::_Worker"], capture_output=True, text=True).stdout
    return [int(p) for p in out.split()]


def test_rollouts_on_ray_are_the_local_ones_and_survive_a_killed_worker(ray_cluster, small_dataset, tmp_path):
    local = collect_rollouts(tmp_path / "local", dataset=small_dataset, workers=1, **PLAN)
    done = {}

    def run():
        done["summary"] = collect_rollouts(tmp_path / "ray", dataset=small_dataset, workers=2, backend="ray",
                                           ray_address=ray_cluster, **PLAN)

    thread = threading.Thread(target=run)
    thread.start()
    deadline = time.time() + 300
    while thread.is_alive() and time.time() < deadline and not any((tmp_path / "ray").glob("chunk-*")):
        time.sleep(0.2)                               # the first episode is in: the workers are mid-collection
    assert thread.is_alive(), "the collection ended before a worker could be killed"
    pids = worker_pids()
    assert pids, "no Ray worker process found"
    os.kill(pids[0], signal.SIGKILL)
    thread.join(600)
    assert not thread.is_alive() and "summary" in done
    assert done["summary"]["collected_now"] == local["episodes"] == done["summary"]["episodes"]
    ray_records, local_records = by_slot(tmp_path / "ray"), by_slot(tmp_path / "local")
    assert ray_records[keys.SLOT].tolist() == list(range(local["episodes"]))     # none lost, none twice
    assert_same_records(ray_records, local_records)                               # bit-identical episodes


def test_evaluate_policy_on_ray_matches_local(ray_cluster, small_dataset_dir, tmp_path):
    evaluate = load_recipe("evaluate_policy")
    common = [f"dataset={small_dataset_dir}", "split=train", "difficulties=[easy,hard]", "episodes_per_level=2",
              "policies=[random,no_manipulation]", "video_episodes=0"]
    for name, extra in (("local", []), ("ray", ["backend=ray", f"ray.address={ray_cluster}"])):
        evaluate.main(compose_recipe_config("evaluate_policy", [*common, *extra, f"out_dir={tmp_path / name}"]))
    for f in sorted((tmp_path / "local" / "episodes").glob("*.pt")):
        a = load_tensors(f, what="episodes", hint="")["metrics"]
        b = load_tensors(tmp_path / "ray" / "episodes" / f.name, what="episodes", hint="")["metrics"]
        assert a.keys() == b.keys() and all(torch.equal(torch.nan_to_num(a[k]), torch.nan_to_num(b[k])) for k in a), f.name


def test_dqn_training_on_ray_learns_like_local_and_resumes(ray_cluster, small_dataset_dir, tmp_path):
    train_dqn = load_recipe("train_dqn")
    base = ["profile=smoke", f"dataset={small_dataset_dir}", "seed=3"]

    def train(*overrides):
        return train_dqn.train(compose_recipe_config("train_dqn", [*base, *overrides]))

    train("collector=multi_sync", "collector.num_workers=2", f"out_dir={tmp_path / 'local'}")
    train("collector=ray", "collector.num_workers=2", f"ray.address={ray_cluster}", f"out_dir={tmp_path / 'ray'}")
    beta = {name: (tmp_path / name / "csv" / "scalars" / "train" / "beta.csv").read_text().split() for name in ("local", "ray")}
    assert beta["ray"] == beta["local"] and len(beta["ray"]) == 4       # β's schedule reached the actors' envs
    updates = {name: (tmp_path / name / "csv" / "scalars" / "train" / "updates.csv").read_text().split()
               for name in ("local", "ray")}
    assert updates["ray"] == updates["local"]
    # resume: 16 more frames on Ray continue from the last checkpoint
    train("collector=ray", "collector.num_workers=2", f"ray.address={ray_cluster}", "resume=true",
          "resume_allow_changes=true", "collector.total_frames=48", f"out_dir={tmp_path / 'ray'}")
    frames = [int(line.split(",")[0]) for line in (tmp_path / "ray" / "csv" / "scalars" / "train" / "beta.csv").read_text().split()]
    assert frames == [8, 16, 24, 32, 40, 48]
