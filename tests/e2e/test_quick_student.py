"""The students' profiles: `student` (recipes/pipeline.py pipeline=student) starts from the shipped recognition file, frozen,
with the budget it promises; `shipped_student` rebuilds the network of checkpoints/dqn_geometric_student."""

import json
import subprocess
import sys

import torch

from omegaconf import OmegaConf
from torchrl.checkpoint import Checkpoint
from torchrl.data import Categorical

from conftest import REPO, compose_recipe_config
from mqa_rl.data.objects import CLASS_NAMES
from mqa_rl.modules.push.pretrained_recognition import load_recognition
from mqa_rl.modules.push.push_policy import make_push_qnet, make_q_actor
from mqa_rl.training.resume_guard import flatten
from mqa_rl.sim.geometry import CAMERA_DISTANCE


def test_the_student_profile_loads_the_shipped_recognition_frozen():
    cfg = compose_recipe_config("train_dqn", ["profile=student"])
    assert cfg.demos.pretrain_updates == 2500 and cfg.collector.total_frames == 8
    assert cfg.env.push_memory == 1            # the stop fit and the test run the policy with the memory
    assert cfg.model.geometric_push and cfg.model.rotated_head and cfg.model.class_map
    recognition = REPO / cfg.model.pretrained
    assert recognition.is_file(), f"{recognition} must ship with the repository"
    vocab = torch.load(recognition, map_location="cpu", weights_only=False)["question"]["embedding.weight"].shape[0]
    net = make_push_qnet(cfg.model, vocab_size=vocab, camera_distance=CAMERA_DISTANCE, num_classes=len(CLASS_NAMES))
    before = {k: v.clone() for k, v in net.rgb_trunk.state_dict().items()}
    meta = load_recognition(net, recognition, CLASS_NAMES, freeze=cfg.model.pretrained_frozen)
    assert "dataset_sha256" in meta
    assert any(not torch.equal(before[k], v) for k, v in net.rgb_trunk.state_dict().items())
    assert not any(p.requires_grad for p in net.rgb_trunk.parameters())
    assert not any(p.requires_grad for p in net.class_head.parameters())
    assert all(p.requires_grad for p in net.question.parameters())


def test_the_shipped_student_profile_composes_the_shipped_students_config_and_loads_its_weights():
    """The provenance's command under the profile's new name gives the settings the shipped student was trained
    with; its recognition file is the shipped copy of the same weights (the old path was runs/recognition/)."""
    shipped = flatten(OmegaConf.to_container(OmegaConf.load(REPO / "checkpoints/dqn_geometric_student/config.yaml")))
    cfg = compose_recipe_config("train_dqn", ["dataset=data/mqa", "reward=global", "profile=shipped_student",
                                              "out_dir=runs/geometric_student"])
    composed = flatten(OmegaConf.to_container(cfg, resolve=False))
    differ = {k: (shipped[k], composed[k]) for k in shipped.keys() & composed.keys() if shipped[k] != composed[k]}
    assert differ == {"model.pretrained": ("runs/recognition/recognition.pt", "checkpoints/recognition/recognition.pt"),
                      "logger.progress": (False, True)}
    vocab = torch.load(REPO / cfg.model.pretrained, map_location="cpu", weights_only=False)["question"]["embedding.weight"].shape[0]
    net = make_push_qnet(cfg.model, vocab_size=vocab, camera_distance=CAMERA_DISTANCE, num_classes=len(CLASS_NAMES))
    actor = make_q_actor(net, Categorical(6273))
    before = {k: v.clone() for k, v in net.state_dict().items()}
    checkpoint = REPO / "checkpoints/dqn_geometric_student/checkpoints/checkpoint-000000000008"
    Checkpoint(policy=actor).load(checkpoint, components=["policy"], strict="error", map_location="cpu")
    assert any(not torch.equal(before[k], v) for k, v in net.state_dict().items())


def run_quick_chain(root, *overrides):
    """recipes/pipeline.py pipeline=student on ROOT, seed 0, as a user runs it (its default teacher unless given)."""
    return subprocess.run([sys.executable, str(REPO / "recipes" / "pipeline.py"), "pipeline=student", f"root={root}", "seed=0",
                           *overrides], cwd=root.parent, capture_output=True, text=True, timeout=300)


def test_the_quick_chain_names_its_teachers_and_refuses_others(tmp_path):
    done = run_quick_chain(tmp_path / "run", "teacher=bogus")
    assert done.returncode == 2 and "teacher=bogus: choose one of image, refined, countable" in done.stderr
    assert not (tmp_path / "run").exists()                 # refused before anything is written


def test_the_quick_chain_refuses_to_reuse_the_other_teachers_demonstrations(tmp_path):
    demos = tmp_path / "run" / "demos_0"
    demos.mkdir(parents=True)
    (demos / "demos.json").write_text(json.dumps({"states": 600, "oracle": {"refine_radius": 1}}))   # refined teacher's
    done = run_quick_chain(tmp_path / "run")
    assert done.returncode == 2, done.stderr[-2000:]
    assert ("demos_0 holds demonstrations of another teacher (oracle refine_radius, min_visible_fraction, require_gain, "
            "geometry, order = 1 0.3 false visible visible_first), not the image teacher's "
            "(0 0.3 false visible visible_first)") in done.stderr
    assert "set teacher= to match" in done.stderr
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["demos_0"]      # nothing else started
