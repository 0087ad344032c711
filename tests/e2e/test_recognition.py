"""Pretrained recognition for the push Q-network: per-cell class labels from the env, the class-map
state channel, the pretraining loss, the recognition file, and the recipe chain pretrain → demonstrations
→ train_dqn."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.losses.class_cells import ClassCellsLoss
from mqa_rl.modules.push.pretrained_recognition import load_recognition, save_recognition
from mqa_rl.modules.push.push_qnet import PushQNet
from torch_threads import one_torch_thread  # noqa: F401  (autouse)

from conftest import REPO as ROOT
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "WANDB_MODE": "offline", "WANDB_SILENT": "true"}
VOCAB, L, S, CLASSES = 30, 8, 224, 5
SMALL = dict(light_channels=(8, 8, 16, 16), light_downsample=2, fuse_channels=(16, 8), head_channels=(8,))


def _net(**kw):
    return PushQNet(VOCAB, camera_distance=0.9, class_map=True, num_classes=CLASSES, **{**SMALL, **kw})


def _obs(batch=2, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (torch.randint(0, 256, (batch, 3, S, S), dtype=torch.uint8, generator=g),
            0.8 + 0.1 * torch.rand(batch, 1, S, S, generator=g), torch.randint(1, VOCAB, (batch, L), generator=g))


def test_class_cells_partition_every_cell_and_contain_the_target_cells(small_dataset):
    from mqa_rl.envs.sapien_bin import SapienBinEnv

    env = SapienBinEnv(small_dataset, split="train", difficulties=["hard"], seed=3)
    td = env.reset()
    for step in range(2):
        cells = env.class_cells()
        assert cells.shape == (1 + len(small_dataset.classes), actions.GRID, actions.GRID)
        np.testing.assert_allclose(cells.sum(0), 1.0, atol=1e-5)           # every pixel: one class or none
        assert (cells[1:].sum() > 50) and (cells[0].sum() > 50)           # objects and floor both seen
        asked = [1 + small_dataset.classes.index(c) for c in env.question.classes]
        np.testing.assert_allclose(cells[asked].sum(0), td[keys.TARGET_CELLS].numpy(), atol=1e-6)
        td = env.step(td.set(keys.ACTION, torch.tensor(int(td[keys.ACTION_MASK][:-1].nonzero()[40]))))["next"]


def test_class_map_joins_the_state_as_the_questions_attended_class_probabilities():
    net = _net()
    rgb, depth, q = _obs()
    plain = PushQNet(VOCAB, camera_distance=0.9, **SMALL)
    assert net.state(rgb, depth, q).shape[1] == plain.state(rgb, depth, q).shape[1] + 1
    fr = net._grid(net.rgb_trunk(net._align(net.normalise(rgb, depth)[0])))
    w = torch.softmax(net.question_classes(net.question(q)), -1)
    expected = (w[:, :, None, None] * torch.softmax(net.class_head(fr), 1)).sum(1)
    torch.testing.assert_close(net.state(rgb, depth, q)[:, -1], expected)
    torch.testing.assert_close(torch.sigmoid(net.target_logits(rgb, depth, q)), expected.clamp(1e-4, 1 - 1e-4))
    torch.testing.assert_close(net.class_logits(rgb), net.class_head(fr))
    assert net(rgb, depth, q).shape == (2, actions.NUM_ACTIONS)


def _geometric_net():
    torch.manual_seed(0)
    return _net(rotated_head=True, geometric_push=True, head_channels=(8, 8), head_context=1).eval()


def test_geometric_push_maps_read_the_target_map_and_heights_not_the_visual_features():
    """Changing the fused rgb+depth features and the question tile (what the stop branch reads) leaves
    every push map unchanged; changing the heights or the target map changes them."""
    net = _geometric_net()
    rgb, depth, q = _obs()
    with torch.no_grad():
        before = net.q_map(rgb, depth, q)
        for p in (*net.fuse.parameters(), *net.depth_trunk.parameters()):
            p.add_(torch.randn_like(p))
        after = net.q_map(rgb, depth, q)
        torch.testing.assert_close(after[:, :8], before[:, :8])
        assert not torch.allclose(after[:, 8], before[:, 8], atol=1e-4)       # the stop branch does read them
        raised = depth.clone()
        raised[..., 64:128, 64:128] -= 0.2                                      # a 20 cm box in the image
        assert not torch.allclose(net.q_map(rgb, raised, q)[:, :8], before[:, :8], atol=1e-4)
        net.class_head.bias[1:].add_(torch.randn(CLASSES))                     # another target map
        assert not torch.allclose(net.q_map(rgb, depth, q)[:, :8], before[:, :8], atol=1e-4)


def test_geometry_maps_are_the_target_map_presence_and_per_cell_heights():
    net = _geometric_net()
    rgb, _, q = _obs(batch=1)
    depth = torch.full((1, 1, S, S), 0.9)                                       # the floor: camera 0.9 m away
    depth[..., 16:24, 40:48] = 0.7                                              # cell (2, 5) fully 20 cm high
    depth[..., 16:20, 48:56] = 0.8                                              # half of cell (2, 6) 10 cm high
    with torch.no_grad():
        fr = net._rgb_features(rgb)
        probs = torch.softmax(net.class_head(fr), 1)
        t = net._targets(probs, net.question(q))
        geo = net.geometry(probs, depth, t)
    assert geo.shape == (1, 5, actions.GRID, actions.GRID)
    torch.testing.assert_close(geo[:, 0:1], t)
    torch.testing.assert_close(geo[:, 1], 1 - torch.softmax(net.class_head(fr), 1)[:, 0])
    mean, high, low = geo[0, 2:]
    assert (mean[2, 5], high[2, 5], low[2, 5]) == pytest.approx((2.0, 2.0, 2.0), abs=1e-5)   # heights in 0.1 m
    assert (mean[2, 6], high[2, 6], low[2, 6]) == pytest.approx((0.5, 1.0, 0.0), abs=1e-5)
    assert float(geo[0, 2:].abs().sum()) == pytest.approx(3 * 2.0 + 0.5 + 1.0, abs=1e-4) and float(mean[2, 4]) == 0


def test_geometric_push_stays_equivariant_to_quarter_turns():
    net = _geometric_net()
    rgb, depth, q = _obs(batch=1)
    turn = lambda x: torch.rot90(x, 1, dims=(-2, -1))       # noqa: E731
    with torch.no_grad():
        fr, fd, qf, probs, t = net._features(rgb, depth, q)
        state, geo = net._state(fr, fd, qf, t), net.geometry(probs, depth, t)
        qmap, turned = net.head(state, geo), net.head(turn(state), turn(geo))
    for d in range(actions.DIRECTIONS):
        torch.testing.assert_close(turned[:, (d + 2) % 8], turn(qmap[:, d]), atol=1e-5, rtol=1e-4)


def test_geometric_push_needs_the_class_map_and_the_rotated_head():
    with pytest.raises(ValueError, match="geometric_push needs class_map=true"):
        PushQNet(VOCAB, camera_distance=0.9, rotated_head=True, geometric_push=True, **SMALL)
    with pytest.raises(ValueError, match="rotated_head=true"):
        _net(geometric_push=True)


def _coloured_cells(batch, seed):
    """Images whose 8×8 cells each show one of CLASSES flat colours or grey floor, with their labels."""
    g = torch.Generator().manual_seed(seed)
    labels = torch.randint(0, 1 + CLASSES, (batch, actions.GRID, actions.GRID), generator=g)
    palette = torch.tensor([[128, 128, 128], [230, 30, 30], [30, 200, 30], [30, 30, 230], [220, 220, 20], [200, 20, 200]],
                           dtype=torch.uint8)
    rgb = palette[labels].permute(0, 3, 1, 2).repeat_interleave(8, -2).repeat_interleave(8, -1)
    cells = torch.nn.functional.one_hot(labels, 1 + CLASSES).permute(0, 3, 1, 2).to(torch.float16)
    from tensordict import TensorDict

    return TensorDict({keys.RGB: rgb.contiguous(), keys.CLASS_CELLS: cells}, batch_size=[batch])


def test_class_cells_loss_learns_colours_and_reports_accuracy():
    torch.manual_seed(0)
    net = _net()
    loss = ClassCellsLoss(net)
    batch = _coloured_cells(4, 0)
    first = loss(batch)
    optim = torch.optim.Adam([*net.rgb_trunk.parameters(), *net.class_head.parameters()], lr=3e-3)
    for _ in range(60):
        td = loss(batch)
        optim.zero_grad()
        td["loss_class_cells"].backward()
        optim.step()
    last = loss(batch)
    assert last["loss_class_cells"] < 0.5 * first["loss_class_cells"]
    assert last["cell_accuracy"] > 0.8 and last["target_iou"] > 0.5 > first["target_iou"]
    with pytest.raises(ValueError, match="class_map=True"):
        ClassCellsLoss(PushQNet(VOCAB, camera_distance=0.9, **SMALL))
    bad = batch.clone().set(keys.CLASS_CELLS, batch[keys.CLASS_CELLS][:, :3])
    with pytest.raises(ValueError, match="labelled for 2 classes"):
        loss(bad)


def test_recognition_file_round_trip_freezes_and_refuses_what_does_not_fit(tmp_path):
    classes = [f"c{i}" for i in range(CLASSES)]
    source = _net()
    path = save_recognition(source, tmp_path / "rec.pt", classes, {"step": 7})
    assert not list(tmp_path.glob(".rec.pt.tmp*"))                     # written atomically
    net = _net()
    assert load_recognition(net, path, classes) == {"step": 7}
    for a, b in zip(source.rgb_trunk.state_dict().values(), net.rgb_trunk.state_dict().values()):
        assert torch.equal(a, b)
    assert torch.equal(source.class_head.weight, net.class_head.weight)
    assert not any(p.requires_grad for p in (*net.rgb_trunk.parameters(), *net.class_head.parameters()))
    assert all(p.requires_grad for p in (*net.depth_trunk.parameters(), *net.question.parameters()))
    assert torch.equal(source.question_classes.weight, net.question_classes.weight)
    assert all(p.requires_grad for p in _net().class_head.parameters())  # freeze=False leaves them trainable
    with pytest.raises(FileNotFoundError, match="pretrain.py part=push_trunk"):
        load_recognition(_net(), tmp_path / "missing.pt", classes)
    with pytest.raises(ValueError, match="another dataset"):
        load_recognition(_net(), path, list(reversed(classes)))
    with pytest.raises(ValueError, match="light_channels"):
        load_recognition(_net(light_channels=(8, 8, 16, 32)), path, classes)
    with pytest.raises(ValueError, match="class_map=true"):
        load_recognition(PushQNet(VOCAB, camera_distance=0.9, **SMALL), path, classes)
    visual_only = torch.load(path, weights_only=True)         # a file without the question part loads too
    for name in ("question", "question_classes"):
        visual_only.pop(name)
    visual_only["architecture"].pop("question_shapes")
    torch.save(visual_only, tmp_path / "visual.pt")
    fresh = _net()
    before = fresh.question_classes.weight.clone()
    load_recognition(fresh, tmp_path / "visual.pt", classes)
    assert torch.equal(fresh.question_classes.weight, before) and torch.equal(fresh.class_head.weight, source.class_head.weight)
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(ValueError, match="truncated"):
        load_recognition(_net(), truncated, classes)


@pytest.mark.timeout(900)
def test_pretrain_then_train_dqn_from_the_recognition_file(small_dataset_dir, tmp_path):
    rec = tmp_path / "rec"
    args = [str(ROOT / "recipes" / "pretrain.py"), "part=push_trunk", f"dataset={small_dataset_dir}", f"out_dir={rec}",
            "frames.count=24", "frames.max_pushes=3", "train.steps=4", "train.eval_interval=2", "train.batch_size=4",
            "question.steps=300",
            "logger=csv", "logger.progress=false", "threads=1"]
    out = subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "collected 24 frames" in out.stdout and (rec / "recognition.pt").exists()
    summary = json.loads((rec / "summary.json").read_text())
    assert summary["question"]["question/accuracy"] > 0.9     # which class a question asks about: learnt
    again = subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert again.returncode == 0 and "collected" not in again.stdout       # the cached frames are reused
    blob = torch.load(rec / "recognition.pt", weights_only=True)
    demos = tmp_path / "demos"                                  # and the oracle's demonstrations (DQfD)
    out = subprocess.run([sys.executable, str(ROOT / "recipes" / "collect.py"), "what=demonstrations", f"dataset={small_dataset_dir}",
                          f"out_dir={demos}", "states=6", "progress=false", "env.max_pushes=3"],
                         capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0 and "6 demonstrations" in out.stdout, out.stderr[-3000:]
    run = tmp_path / "run"
    train = [str(ROOT / "recipes" / "train_dqn.py"), "profile=smoke", f"dataset={small_dataset_dir}",
             f"out_dir={run}", "threads=1", "model.class_map=true", f"model.pretrained={rec / 'recognition.pt'}",
             "loss.target_map_weight=1.0", f"demos.path=[{demos},{demos}]", "demos.batch_size=4",
             "demos.loss=push_cross_entropy", "demos.smooth_cells=1.0", "demos.stop_margin=0.5", "demos.pretrain_lr=3e-3",
             "buffer.augment=dihedral"]
    out = subprocess.run([sys.executable, *train, "demos.pretrain_updates=3"], capture_output=True, text=True, timeout=600,
                         env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-3000:]
    assert "done: {'frames': 32" in out.stdout and "demonstration pre-training 3/3" in out.stdout
    assert (run / "csv" / "scalars" / "train" / "demo_stop_agreement.csv").exists()
    # a lengthened pre-training continues from the finished run's checkpoint: the 3 updates done are not
    # repeated, their log rows are kept (they are stepped by update, not frame), and a third call has nothing to do
    longer = [*train, "demos.pretrain_updates=5", "demos.checkpoint_updates=1", "demos.weight=0.4", "resume=true",
              "resume_allow_changes=true"]          # a lighter demonstration loss from here on: a deliberate change
    out = subprocess.run([sys.executable, *longer], capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-3000:]
    assert "changed settings:\n  demos.weight: 0.5 -> 0.4" in out.stdout
    assert "3 demonstration pre-training updates" in out.stdout and "'demo_pretrain_updates': 5" in out.stdout
    assert "pre-training 4/5" not in out.stdout and "demonstration pre-training 5/5" in out.stdout
    logged = (run / "csv" / "scalars" / "demo_pretrain" / "loss_demo.csv").read_text().split()
    assert [row.split(",")[0] for row in logged] == ["3", "5"]
    assert "pretrain_updates: 5" in (run / "config.yaml").read_text()      # the config of the newest checkpoint
    out = subprocess.run([sys.executable, *longer], capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0 and "5 demonstration pre-training updates" in out.stdout
    assert "demonstration pre-training 5/5" not in out.stdout
    figures = tmp_path / "figures"
    out = subprocess.run([sys.executable, str(ROOT / "recipes" / "evaluate_policy.py"), f"plot=[{run}]", f"out_dir={figures}"],
                         capture_output=True, text=True, timeout=300, env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    assert (figures / "fig7_rewards_pretraining.png").stat().st_size > 0 and (figures / "fig7_rewards.png").stat().st_size > 0
    # the frozen recognition is unchanged by DQN training, and the trained policy loads for evaluation
    from mqa_rl.envs.sapien_bin import SapienBinEnv
    from mqa_rl.modules.push.trained_policy import load_greedy

    actor, _, _ = load_greedy(run, None, SapienBinEnv(small_dataset_dir, split="test"))
    net = actor.module[0].module if hasattr(actor.module[0], "module") else None
    net = next(m for m in actor.modules() if isinstance(m, PushQNet)) if net is None else net
    for name, value in blob["class_head"].items():
        assert torch.equal(net.class_head.state_dict()[name], value)
    # the recognition a trained run carries, extracted as a file: the pretraining's visual weights, which
    # start a new run (here a geometric student: its push branch reads the target map and heights)
    extracted = tmp_path / "extracted" / "recognition.pt"
    extract = [sys.executable, str(ROOT / "recipes" / "export_policy.py"), "export=recognition", f"run={run}",
               f"out_dir={extracted.parent}"]
    out = subprocess.run(extract, capture_output=True, text=True, timeout=300, env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    again = torch.load(extracted, weights_only=True)
    assert again["meta"]["extracted_from"].endswith(net_checkpoint_name(run))
    for part in ("rgb_trunk", "class_head"):
        assert all(torch.equal(again[part][k], v) for k, v in blob[part].items()), part
    out = subprocess.run(extract, capture_output=True, text=True, timeout=300, env=ENV, cwd=tmp_path)
    assert out.returncode != 0 and "overwrite=true" in out.stderr              # never replaced silently
    geometric = [*train[:3], f"out_dir={tmp_path / 'geometric'}", *train[4:6], f"model.pretrained={extracted}",
                 *train[7:], "model.rotated_head=true", "model.geometric_push=true", "model.head_channels=[8,8]",
                 "demos.pretrain_updates=2", "collector.total_frames=8"]
    out = subprocess.run([sys.executable, *geometric], capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-3000:]
    written = (tmp_path / "geometric" / "config.yaml").read_text()
    assert "demonstration pre-training 2/2" in out.stdout and "geometric_push: true" in written
    # when to stop, learnt from the geometric student's own episodes on the training split, then used to evaluate it
    fit = [sys.executable, str(ROOT / "recipes" / "fit_stop.py"), f"run={tmp_path / 'geometric'}", f"out_dir={tmp_path / 'stop'}",
           "episodes_per_level=4", "difficulties=[hard]", "holdout_fraction=0.5", "critic.steps=20", "threads=1"]
    out = subprocess.run(fit, capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0 and "stop critic:" in out.stdout, out.stdout[-2000:] + out.stderr[-3000:]
    report = json.loads((tmp_path / "stop" / "report.json").read_text())
    assert 1 <= report["final"]["hard"]["episodes"] <= 4 and report["final"]["hard"]["hindsight"] <= report["final"]["hard"]["after_0"]
    out = subprocess.run([*fit, "split=test", "overwrite=true"], capture_output=True, text=True, timeout=300, env=ENV, cwd=tmp_path)
    assert out.returncode != 0 and "split=train" in out.stderr
    out = subprocess.run(fit, capture_output=True, text=True, timeout=300, env=ENV, cwd=tmp_path)
    assert out.returncode != 0 and "overwrite=true" in out.stderr            # a fitted critic is never replaced silently
    ev = tmp_path / "eval_stop"
    out = subprocess.run([sys.executable, str(ROOT / "recipes" / "evaluate_policy.py"), f"run={tmp_path / 'geometric'}",
                          f"stop_critic={tmp_path / 'stop'}", "episodes_per_level=2", "difficulties=[hard]", "policies=[greedy]",
                          "video_episodes=0", f"out_dir={ev}"], capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    assert json.loads((ev / "results.json").read_text())["hard"]["greedy"]["pushes"]["n"] == 2
    from mqa_rl.modules.frozen_policies import make_frozen_policy
    from mqa_rl.modules.stop.learned_stop import LearnedStop

    spec = {"kind": "dqn", "run": str(tmp_path / "geometric"), "stop_critic": str(tmp_path / "stop")}
    policy, _ = make_frozen_policy(spec, SapienBinEnv(small_dataset_dir, split="test"), max_pushes=3)
    assert isinstance(policy, LearnedStop)                               # an answering system can use it too
    with pytest.raises(ValueError, match="not both"):
        make_frozen_policy({**spec, "stop_margin": 0.5}, None, max_pushes=3)
    out = subprocess.run([sys.executable, str(ROOT / "recipes" / "evaluate_policy.py"), f"run={run}",
                          f"stop_critic={tmp_path / 'stop'}", "episodes_per_level=1", "difficulties=[hard]", "policies=[greedy]",
                          "video_episodes=0", f"out_dir={ev}"], capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode != 0 and "another policy" in out.stderr          # fitted for the geometric student, not this run
    # a stop that also reads a counting perception trained at a finer render (448 px): the env renders its answer
    # camera in every state, the critic's file names the perception, a collection of its system runs with those frames
    from mqa_rl.collectors.rollouts import collect_rollouts
    from mqa_rl.data.dataset import MQADataset
    from mqa_rl.modules.answering.perception import CountingPerception, save_perception
    from mqa_rl.modules.stop.learned_stop import StopCritic

    classes = len(MQADataset(small_dataset_dir).classes)
    perception = save_perception(CountingPerception(1 + classes, widths=(8, 8, 16, 16), image_size=448),
                                 tmp_path / "perception.pt", {})
    out = subprocess.run([*fit[:3], f"out_dir={tmp_path / 'stop_read'}", *fit[4:], "value=uncountable",
                          f"perception={perception}"], capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0 and "stop critic:" in out.stdout, out.stdout[-2000:] + out.stderr[-3000:]
    critic, _ = StopCritic.load(tmp_path / "stop_read")
    assert critic.reading is not None and critic.reading.input_size == 448
    plan = dict(dataset=small_dataset_dir, policy={**spec, "stop_critic": str(tmp_path / "stop_read")}, split="train",
                levels=["hard"], max_per_group=1, max_pushes=2, workers=1, store_depth=False, progress=False)
    collect_rollouts(tmp_path / "read_rollouts", **plan)
    env_meta = json.loads((tmp_path / "read_rollouts" / "meta.json").read_text())["env"]
    assert env_meta["answer_size"] == 448 and env_meta["answer_observation"] is True
    with pytest.raises(ValueError, match="collection.env.answer_size=448"):
        collect_rollouts(tmp_path / "read_other", **plan, answer_size=672)


def net_checkpoint_name(run: Path) -> str:
    """The newest checkpoint folder's name of a train_dqn.py run."""
    return sorted(p.name for p in (run / "checkpoints").glob("checkpoint-*"))[-1]
