"""TrainingCheckpoint restores a run exactly: weights, target net, optimiser, replay contents and
priorities, ε, β counter, run counters and RNG; a damaged checkpoint gives a clear error."""

import random
import shutil

import numpy as np
import pytest
import torch
from torchrl.data import Categorical

from mqa_rl import keys
from mqa_rl.collectors.replay import compact_transitions, make_replay_buffer
from mqa_rl.envs import actions
from mqa_rl.losses.dqn import make_dqn_loss
from mqa_rl.modules.push.push_policy import make_explorer, make_push_qnet, make_q_actor
from mqa_rl.training.checkpoint import TrainingCheckpoint
from mqa_rl.verified_checkpoint import CheckpointCorrupt
from test_dqn_learning import SMALL_NET, VOCAB, transitions
from torch_threads import one_torch_thread  # noqa: F401  (autouse)


def build(tmp_path, name, seed):
    torch.manual_seed(seed)
    spec = Categorical(actions.NUM_ACTIONS)
    net = make_push_qnet(SMALL_NET, vocab_size=VOCAB, camera_distance=0.9)
    actor = make_q_actor(net, spec)
    explore = make_explorer(actor, spec, eps_init=1.0, eps_end=0.1, annealing_frames=100)
    loss, updater = make_dqn_loss(actor, {"gamma": 0.6, "target_update": {"kind": "hard", "interval": 3}})
    opt = torch.optim.Adam([p for p in loss.parameters() if p.requires_grad], lr=1e-3)
    rb = make_replay_buffer({"size": 16, "batch_size": 4, "alpha": 0.6, "beta_init": 0.4}, tmp_path / f"scratch_{name}")
    counter = torch.zeros((), dtype=torch.int64)
    state = {"frames": 0, "updates": 0, "episodes": 0}
    ckpt = TrainingCheckpoint(tmp_path / "ckpt", actor=actor, loss=loss, optimizer=opt, replay_buffer=rb,
                              egreedy=explore[-1], target_updater=updater, beta_counter=counter, state=state)
    return dict(actor=actor, loss=loss, updater=updater, opt=opt, rb=rb, eg=explore[-1], counter=counter,
                state=state, ckpt=ckpt)


def train_a_little(run):
    run["rb"].extend(compact_transitions(transitions(12, seed=3)))
    for _ in range(4):
        s = run["rb"].sample()
        out = run["loss"](s)
        run["opt"].zero_grad()
        out["loss"].backward()
        run["opt"].step()
        run["updater"].step()
        run["rb"].update_tensordict_priority(s)
    run["rb"].sampler.beta = 0.7
    run["eg"].step(37)
    run["counter"].fill_(12)
    run["state"].update(frames=12, updates=4, episodes=2)


def test_save_then_load_restores_the_exact_state(tmp_path):
    a = build(tmp_path, "a", seed=0)
    train_a_little(a)
    path = a["ckpt"].save()
    assert path.name.endswith("12") and a["ckpt"].latest() == path
    b = build(tmp_path, "b", seed=1)
    torch.manual_seed(99)
    assert b["ckpt"].load() == path
    for pa, pb in zip(a["loss"].state_dict().values(), b["loss"].state_dict().values()):   # online + target
        assert torch.equal(pa, pb)
    assert any(k.startswith("target_value_network_params") for k in b["loss"].state_dict())
    for pa, pb in zip(a["actor"].parameters(), b["actor"].parameters()):
        assert torch.equal(pa, pb)
    sa, sb = a["opt"].state_dict(), b["opt"].state_dict()
    assert sa["state"].keys() == sb["state"].keys()
    for k in sa["state"]:
        assert torch.equal(sa["state"][k]["exp_avg"], sb["state"][k]["exp_avg"])
    assert len(b["rb"]) == len(a["rb"]) == 12
    assert torch.equal(b["rb"][:][keys.RGB], a["rb"][:][keys.RGB])
    assert torch.equal(b["rb"][:]["next", keys.DEPTH], a["rb"][:]["next", keys.DEPTH])
    pa = torch.tensor([a["rb"].sampler._sum_tree[i] for i in range(12)])
    pb = torch.tensor([b["rb"].sampler._sum_tree[i] for i in range(12)])
    assert torch.equal(pa, pb) and not torch.allclose(pa, pa[0].expand(12))   # priorities, not the default
    assert b["rb"].sampler.beta == pytest.approx(0.7)
    assert b["eg"].eps == pytest.approx(a["eg"].eps) and b["eg"].eps < 1.0
    assert int(b["counter"]) == 12 and b["state"] == a["state"]
    assert b["updater"].counter == a["updater"].counter


def test_a_checkpoint_before_the_first_frame_holds_no_buffer_and_restores(tmp_path):
    """Demonstration pre-training saves before any frame: the empty replay buffer is left out (TorchRL
    cannot save an uninitialised storage), the rest restores; a buffer-less checkpoint after frames is refused."""
    a = build(tmp_path, "a", seed=0)
    a["opt"].step()                                            # something to restore beyond the weights
    a["state"].update(demo_pretrain_updates=7)
    path = a["ckpt"].save()
    assert not list((path / "components").glob("*replay_buffer*"))
    b = build(tmp_path, "b", seed=1)
    assert b["ckpt"].load() == path and b["state"]["demo_pretrain_updates"] == 7 and len(b["rb"]) == 0
    for pa, pb in zip(a["actor"].parameters(), b["actor"].parameters()):
        assert torch.equal(pa, pb)
    b["rb"].extend(compact_transitions(transitions(4, seed=3)))   # the restored run fills its buffer as usual
    assert len(b["rb"]) == 4
    a["state"].update(frames=8)                               # a forged counter: frames but no buffer
    a["ckpt"].save()
    with pytest.raises(CheckpointCorrupt, match="no replay buffer after 8 frames"):
        build(tmp_path, "c", seed=2)["ckpt"].load()


def test_rng_state_round_trips(tmp_path):
    a = build(tmp_path, "a", seed=0)
    train_a_little(a)
    a["ckpt"].save()
    draws = (torch.rand(4), random.random(), np.random.rand(2))
    b = build(tmp_path, "b", seed=1)     # moves the torch generator on
    random.random()
    np.random.rand(7)
    b["ckpt"].load()
    again = (torch.rand(4), random.random(), np.random.rand(2))
    assert torch.equal(draws[0], again[0]) and draws[1] == again[1] and np.array_equal(draws[2], again[2])


def test_a_damaged_checkpoint_gives_a_clear_error(tmp_path):
    a = build(tmp_path, "a", seed=0)
    train_a_little(a)
    path = a["ckpt"].save()
    policy_dir = next((path / "components").glob("*policy"))
    victim = next(policy_dir.rglob("*.memmap"))
    victim.write_bytes(victim.read_bytes()[:3])           # truncated weights
    b = build(tmp_path, "b", seed=1)
    with pytest.raises(CheckpointCorrupt, match="cannot be restored.*changed since saved.*resume=false"):
        b["ckpt"].load()
    assert torch.equal(b["eg"].eps, torch.tensor(1.0))       # nothing was restored from it
    shutil.rmtree(path)
    path = a["ckpt"].save()
    (path / "manifest.json").write_text("{ not json")
    with pytest.raises(CheckpointCorrupt, match=str(path.name)):
        b["ckpt"].load(path)
    shutil.rmtree(path)
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        b["ckpt"].load()


def test_an_unreadable_newest_checkpoint_is_named_not_skipped(tmp_path):
    a = build(tmp_path, "a", seed=0)
    train_a_little(a)
    older = a["ckpt"].save()
    a["state"]["frames"] = 20
    newest = a["ckpt"].save()
    assert a["ckpt"].latest() == newest
    (newest / "manifest.json").write_text("{ not json")
    # resuming from the older one silently would repeat frames; the user decides, told which to delete
    with pytest.raises(CheckpointCorrupt, match=f"{newest.name}.*newest readable one is {older.name}.*delete"):
        a["ckpt"].latest()
    (older / "manifest.json").unlink()
    with pytest.raises(CheckpointCorrupt, match=f"{older.name}.*{newest.name}.*cannot be read"):
        a["ckpt"].latest()                                   # none readable: never "no checkpoint, start afresh"
    shutil.rmtree(newest)
    shutil.rmtree(older)
    assert a["ckpt"].latest() is None


def _reseal(checkpoint: "Path") -> None:
    """Rewrite the checkpoint's SHA-256 record over its files as they are now (what anyone handing a user a
    crafted checkpoint can do: the record sits beside the files)."""
    import json

    from mqa_rl.verified_checkpoint import _digests

    record = next((checkpoint / "components").glob("*zz_integrity/sha256.json"))
    record.write_text(json.dumps(_digests(checkpoint / "components", record.parent), indent=0))


def test_a_checkpoint_holds_no_pickle_and_a_planted_one_is_refused_never_run(tmp_path):
    """TorchRL's replay dumps add prefetch.pkl; ours are saved without it. A pickle planted anywhere in a
    checkpoint (the replay's prefetch.pkl, an other.pickle leaf beside the policy's tensors), even with the
    SHA-256 record resealed, is refused naming the file before anything is read, and its code never runs."""
    import pickle

    from test_crafted_files import RAN, Payload

    a = build(tmp_path, "a", seed=0)
    train_a_little(a)
    path = a["ckpt"].save()
    assert not [f for f in path.rglob("*") if f.suffix in (".pkl", ".pickle")]
    for planted in (next(path.glob("components/*-replay_buffer")) / "prefetch.pkl",
                    next(path.glob("components/*-policy")) / "state" / "other.pickle"):
        planted.write_bytes(pickle.dumps(Payload()))
        _reseal(path)
        b = build(tmp_path, "b", seed=1)
        with pytest.raises(CheckpointCorrupt, match=f"pickled file, {planted}.*never unpickled"):
            b["ckpt"].load()
        assert RAN == []
        planted.unlink()
    _reseal(path)
    assert build(tmp_path, "c", seed=2)["ckpt"].load() == path          # the same checkpoint, clean again


def test_snapshots_keep_every_curve_point_with_the_network_alone(tmp_path):
    from torchrl.checkpoint import Checkpoint
    from mqa_rl.verified_checkpoint import IntegrityAdapter
    a = build(tmp_path, "a", seed=0)
    train_a_little(a)
    first = a["ckpt"].snapshot()
    a["state"]["frames"] = 24
    second = a["ckpt"].snapshot()
    assert first.parent == second.parent == tmp_path / "snapshots" and first != second and first.exists()  # none pruned
    components = set(Checkpoint.manifest(second)["components"])
    assert "policy" in components and "replay_buffer" not in components and "optimizer" not in components
    IntegrityAdapter.verify(second, component="policy")
    b = build(tmp_path, "b", seed=1)
    Checkpoint(policy=b["actor"]).load(first, components=["policy"], strict="error")
    for pa, pb in zip(a["actor"].parameters(), b["actor"].parameters()):
        assert torch.equal(pa, pb)
    assert b["ckpt"].latest() is None                      # a snapshot is not a checkpoint a run resumes from
