"""DQN loss and prioritized replay on push-Q-network batches: learning moves the TD error, updates
move the priorities, the replay stores compact transitions."""

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.data import Categorical

from mqa_rl import keys
from mqa_rl.collectors.replay import REPLAY_KEYS, annealed_is_beta, compact_transitions, make_replay_buffer, transition_bytes
from mqa_rl.envs import actions
from mqa_rl.losses.dqn import make_dqn_loss
from mqa_rl.modules.push.push_policy import make_push_qnet, make_q_actor
from mqa_rl.sim.geometry import BinSpec, CameraSpec
from torch_threads import one_torch_thread  # noqa: F401  (autouse)

VOCAB, L, S = 30, 8, 224
SMALL_NET = {"trunk": "light", "light_channels": [8, 8, 16, 16], "fuse_channels": [16, 8], "head_channels": [8],
             "question_dim": 8, "head_context": 1, "coords": True}


def transitions(n: int, seed: int = 0) -> TensorDict:
    """Collected-like transitions (with info, which the replay drops)."""
    g = torch.Generator().manual_seed(seed)
    mask = actions.push_start_mask(BinSpec(), CameraSpec(), np.full((S, S), CameraSpec().distance))
    allowed = mask.nonzero().squeeze(-1)

    def obs():
        return {keys.RGB: torch.randint(0, 256, (n, 3, S, S), dtype=torch.uint8, generator=g),
                keys.DEPTH: 0.8 + 0.1 * torch.rand(n, 1, S, S, generator=g),
                keys.QUESTION: torch.randint(1, VOCAB, (n, L), generator=g),
                keys.ACTION_MASK: mask.expand(n, -1).clone(),
                keys.INFO: {"overlap": torch.rand(n, 50, generator=g),
                            "target_cells": (torch.rand(n, actions.GRID, actions.GRID, generator=g) > 0.9).float()}}

    nxt = obs()
    nxt.update({keys.REWARD: torch.randn(n, 1, generator=g), "done": torch.zeros(n, 1, dtype=torch.bool),
                "terminated": torch.zeros(n, 1, dtype=torch.bool), "truncated": torch.zeros(n, 1, dtype=torch.bool)})
    return TensorDict({**obs(), keys.ACTION: allowed[torch.randint(len(allowed), (n,), generator=g)], "next": nxt}, [n])


def learner(lr=1e-3, **loss_cfg):
    torch.manual_seed(0)
    net = make_push_qnet(SMALL_NET, vocab_size=VOCAB, camera_distance=0.9)
    actor = make_q_actor(net, Categorical(actions.NUM_ACTIONS))
    loss, updater = make_dqn_loss(actor, {"gamma": 0.6, **loss_cfg})
    opt = torch.optim.Adam([p for p in loss.parameters() if p.requires_grad], lr=lr)
    return actor, loss, updater, opt


@pytest.mark.parametrize("function,double", [("huber", True), ("mse", False)])
def test_one_update_lowers_the_td_error_on_a_fixed_batch(function, double):
    _, loss, updater, opt = learner(function=function, double_dqn=double)
    batch = compact_transitions(transitions(8))
    before = batch.clone()
    out = loss(before)
    opt.zero_grad()
    out["loss"].backward()
    opt.step()
    updater.step()
    after = batch.clone()
    loss(after)
    assert after[keys.TD_ERROR].sum() < before[keys.TD_ERROR].sum()


def test_double_dqn_bootstraps_from_the_best_allowed_next_push():
    """The next state's action_mask binds the online argmax of double DQN: with one push allowed there,
    the TD target is r + γ Q_target(s', that push), not the unmasked maximum."""
    actor, loss, _, _ = learner(double_dqn=True)
    batch = compact_transitions(transitions(4))
    with torch.no_grad():
        q = actor(batch.exclude("next").clone())[keys.ACTION_VALUE]
        q_next = actor(batch["next"].clone())[keys.ACTION_VALUE]           # target = online at the start
    allowed = batch["next", keys.ACTION_MASK][0].nonzero().squeeze(-1)
    only = allowed[q_next[:, allowed].mean(0).argmin()]                    # never the unmasked argmax
    assert (q_next.argmax(-1) != only).all()
    batch["next", keys.ACTION_MASK].zero_()
    batch["next", keys.ACTION_MASK][:, only] = True
    loss(batch)
    r = batch["next", keys.REWARD].squeeze(-1)
    chosen = q.gather(-1, batch[keys.ACTION].unsqueeze(-1)).squeeze(-1)
    expected = (chosen - (r + 0.6 * q_next[:, only])) ** 2
    assert torch.allclose(batch[keys.TD_ERROR].squeeze(-1), expected, rtol=1e-4, atol=1e-6)


def test_soft_target_update_moves_the_target_by_tau():
    _, loss, updater, opt = learner(target_update={"kind": "soft", "tau": 0.25})
    online = loss.value_network_params.flatten_keys()
    target = loss.target_value_network_params.flatten_keys()
    name = next(k for k in online.keys() if k.endswith("weight"))
    before = target[name].clone()
    out = loss(compact_transitions(transitions(4)))
    opt.zero_grad()
    out["loss"].backward()
    opt.step()
    updater.step()
    moved = loss.target_value_network_params.flatten_keys()[name]
    now = loss.value_network_params.flatten_keys()[name]
    assert not torch.equal(now, before)
    assert torch.allclose(moved, 0.75 * before + 0.25 * now, atol=1e-6)


def test_priorities_change_after_an_update(tmp_path):
    _, loss, updater, opt = learner()
    rb = make_replay_buffer({"size": 32, "batch_size": 8, "alpha": 0.6, "beta_init": 0.4}, tmp_path / "rb")
    rb.extend(compact_transitions(transitions(32)))
    sample = rb.sample()
    idx = sample["index"]
    old = torch.tensor([rb.sampler._sum_tree[int(i)] for i in idx])
    assert "priority_weight" in sample.keys()
    out = loss(sample)
    opt.zero_grad()
    out["loss"].backward()
    opt.step()
    rb.update_tensordict_priority(sample)
    new = torch.tensor([rb.sampler._sum_tree[int(i)] for i in idx])
    expected = (sample[keys.TD_ERROR].squeeze(-1).double() + rb.sampler._eps) ** 0.6
    assert not torch.allclose(old, new)
    assert torch.allclose(new.double(), expected, rtol=1e-4)


def test_replay_keeps_only_what_the_loss_reads_compactly(tmp_path):
    data = transitions(4)
    stored = compact_transitions(data)
    assert set(stored.keys(True, True)) == set(REPLAY_KEYS)
    assert stored[keys.RGB].dtype == torch.uint8 and stored["next", keys.DEPTH].dtype == torch.float16
    assert (stored[keys.DEPTH].float() - data[keys.DEPTH]).abs().max() < 1e-3     # float16: < 1 mm at 0.9 m
    per = transition_bytes(stored[0])
    assert 2 * 3 * S * S < per < 2 * (3 * S * S + 2 * S * S + actions.NUM_ACTIONS) + 2 * actions.GRID ** 2 + 1024   # uint8 rgb, 2-byte depth and target cells
    # the loss runs on what the replay stores
    _, loss, _, _ = learner()
    loss(stored)
    with pytest.raises(ValueError, match="buffer.storage"):
        make_replay_buffer({"size": 8, "batch_size": 4, "storage": "floppy"}, tmp_path)
    with pytest.raises(ValueError, match="must be ≥"):
        make_replay_buffer({"size": 2, "batch_size": 4}, tmp_path)


def test_is_beta_anneals_to_one_and_bad_loss_configs_fail():
    assert annealed_is_beta(0.4, 0.0) == 0.4 and annealed_is_beta(0.4, 0.5) == pytest.approx(0.7)
    assert annealed_is_beta(0.4, 2.0) == 1.0
    actor = learner()[0]
    with pytest.raises(ValueError, match="loss.function"):
        make_dqn_loss(actor, {"function": "hinge"})
    with pytest.raises(ValueError, match="loss.gamma"):
        make_dqn_loss(actor, {"gamma": 1.5})
    with pytest.raises(ValueError, match="target_update.kind"):
        make_dqn_loss(actor, {"target_update": {"kind": "sometimes"}})


def test_target_map_loss_learns_where_the_targets_are_and_refuses_a_net_without_class_map():
    """The auxiliary loss trains the class map and the question's attention on the stored visible-target
    cells; its gradient reaches the rgb trunk (shared with the DQN loss), and it lowers on a fixed batch."""
    from mqa_rl.losses.target_map import TargetMapLoss

    torch.manual_seed(0)
    net = make_push_qnet({**SMALL_NET, "class_map": True}, vocab_size=VOCAB, camera_distance=0.9)
    aux = TargetMapLoss(net, weight=1.0)
    batch = compact_transitions(transitions(8))
    assert batch[keys.TARGET_CELLS].dtype == torch.float16
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    first = aux(batch)
    first["loss_target_map"].backward()
    assert net.rgb_trunk.body[0].weight.grad.abs().sum() > 0          # reaches the visual trunk
    opt.step()
    for _ in range(30):
        opt.zero_grad()
        aux(batch)["loss_target_map"].backward()
        opt.step()
    assert aux(batch)["loss_target_map"] < 0.5 * first["loss_target_map"]
    with pytest.raises(ValueError, match="class_map=True"):
        TargetMapLoss(make_push_qnet(SMALL_NET, vocab_size=VOCAB, camera_distance=0.9))
    with pytest.raises(KeyError, match="target_cells"):
        aux(batch.exclude(keys.TARGET_CELLS))
