"""DQN from demonstrations: the oracle's states and actions, DQfD's large-margin loss, the recipe."""

import json

import pytest
import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.losses.demonstration import DemonstrationLoss
from mqa_rl.modules.push.push_qnet import PushQNet
from mqa_rl.envs.dihedral import DihedralAugment, transform_action
from torch_threads import one_torch_thread  # noqa: F401  (autouse)

VOCAB, L, S = 30, 8, 224
SMALL = dict(light_channels=(8, 8, 16, 16), light_downsample=2, fuse_channels=(16, 8), head_channels=(8,), head_context=1)


def _fit(net, loss, demos, steps):
    """``steps`` Adam updates of ``loss`` on the fixed demonstrations; the last loss output."""
    optim = torch.optim.Adam(net.parameters(), lr=3e-3)
    for _ in range(steps):
        td = loss(demos)
        optim.zero_grad()
        td["loss_demo"].backward()
        optim.step()
    return td


def _hard_scene_truths(dataset, episodes=6):
    """(env, ground truth) after each of ``episodes`` resets on hard train scenes."""
    from mqa_rl.envs.sapien_bin import SapienBinEnv

    env = SapienBinEnv(dataset, split="train", difficulties=["hard"], seed=0)
    for _ in range(episodes):
        env.reset()
        yield env, env.ground_truth()


def _demos(n=4, seed=0):
    g = torch.Generator().manual_seed(seed)
    mask = torch.ones(n, actions.NUM_ACTIONS, dtype=torch.bool)
    mask[:, :100] = False                                           # some pushes forbidden
    return TensorDict({keys.RGB: torch.randint(0, 256, (n, 3, S, S), dtype=torch.uint8, generator=g),
                       keys.DEPTH: (0.8 + 0.1 * torch.rand(n, 1, S, S, generator=g)).half(),
                       keys.QUESTION: torch.randint(1, VOCAB, (n, L), generator=g), keys.ACTION_MASK: mask,
                       keys.TARGET_CELLS: torch.rand(n, actions.GRID, actions.GRID, generator=g).half(),
                       keys.ACTION: torch.tensor([1000, 2500, actions.STOP, 4000][:n])}, [n])


def test_margin_loss_teaches_the_demonstrated_actions_and_skips_masked_ones():
    torch.manual_seed(0)
    net = PushQNet(VOCAB, camera_distance=0.9, **SMALL)
    loss = DemonstrationLoss(net, margin=0.5)
    demos = _demos()
    first = loss(demos)
    _fit(net, loss, demos, 80)
    last = loss(demos)
    assert last["loss_demo"] < 0.1 * first["loss_demo"]
    assert last["demo_agreement"] == 1.0 and last["demo_near"] == 1.0 and first["demo_agreement"] < 1.0
    with torch.no_grad():                      # the demonstrated action out-values every other allowed one
        q = net(demos[keys.RGB], demos[keys.DEPTH], demos[keys.QUESTION]).masked_fill(~demos[keys.ACTION_MASK], -1e9)
        assert torch.equal(q.argmax(-1), demos[keys.ACTION])
    masked = demos.clone()
    masked[keys.ACTION] = torch.tensor([5, 6, 7, 8])                 # all forbidden by the mask: nothing to learn
    out = loss(masked)
    assert out["loss_demo"].item() == 0.0
    with pytest.raises(ValueError, match="margin and weight"):
        DemonstrationLoss(net, margin=0.0)


def test_dihedral_augment_turns_demonstrations_without_successor_states():
    demos = _demos()
    g = torch.Generator().manual_seed(1)
    out = DihedralAugment(generator=g).forward(demos.clone())
    picks = torch.randint(0, 8, (4,), generator=torch.Generator().manual_seed(1))
    for i, p in enumerate(picks.tolist()):
        expect = transform_action(demos[keys.ACTION][i:i + 1], p % 4, p >= 4)
        assert out[keys.ACTION][i] == expect[0]


def test_oracle_demonstrations_are_collected_and_refused_when_they_do_not_fit(small_dataset, small_dataset_dir, tmp_path):
    from mqa_rl.collectors.demonstrations import DEMO_KEYS, DEMOS_META, collect_demonstrations, load_demonstrations
    from mqa_rl.envs.sapien_bin import SapienBinEnv

    env = SapienBinEnv(small_dataset, split="train", difficulties=["hard"], seed=0)
    demos = collect_demonstrations(env, 5, progress=False)
    assert demos.shape == (5,) and all(k in demos.keys(True) for k in DEMO_KEYS)
    assert demos[keys.DEPTH].dtype == torch.float16 and demos[keys.RGB].dtype == torch.uint8
    pushes = demos[keys.ACTION][demos[keys.ACTION] != actions.STOP]
    assert len(pushes) >= 3                                  # hard scenes: the oracle pushes occluders away
    with pytest.raises(FileNotFoundError, match="collect.py what=demonstrations"):
        load_demonstrations(tmp_path / "none")
    folder = tmp_path / "demos"
    demos.memmap(folder / "data")
    (folder / DEMOS_META).write_text(json.dumps({"dataset_sha256": "something else"}))
    with pytest.raises(ValueError, match="another dataset"):
        load_demonstrations(folder, small_dataset_dir)
    assert torch.equal(load_demonstrations(folder)[keys.ACTION], demos[keys.ACTION])
    assert len(load_demonstrations([folder, folder])) == 10                  # two folders together


def test_push_cross_entropy_learns_demonstrated_pushes_and_leaves_stops_to_td():
    torch.manual_seed(0)
    net = PushQNet(VOCAB, camera_distance=0.9, **SMALL)
    loss = DemonstrationLoss(net, kind="push_cross_entropy")
    demos = _demos()                                   # one of the four demonstrations is a stop
    first = loss(demos)
    _fit(net, loss, demos, 60)
    assert loss(demos)["loss_demo"] < 0.2 * first["loss_demo"]
    with torch.no_grad():
        q = net(demos[keys.RGB], demos[keys.DEPTH], demos[keys.QUESTION])
        pushes = demos[keys.ACTION] != actions.STOP
        allowed = demos[keys.ACTION_MASK].clone()
        allowed[:, actions.STOP] = False
        assert torch.equal(q.masked_fill(~allowed, -1e9).argmax(-1)[pushes], demos[keys.ACTION][pushes])
    only_stops = demos[2:3]
    assert loss(only_stops)["loss_demo"].item() == 0.0
    with pytest.raises(ValueError, match="unknown demonstration loss"):
        DemonstrationLoss(net, kind="bc")


def test_visible_first_oracle_serves_partly_visible_targets_first(small_dataset):
    import numpy as np

    from mqa_rl.modules.push.privileged_policy import PrivilegedPushPolicy

    checked = 0
    for env, gt in _hard_scene_truths(small_dataset):
        visible_first = PrivilegedPushPolicy(env, lookahead=1, order="visible_first")
        unrevealed = np.flatnonzero(gt["target"] & ~visible_first.revealed(gt["visible"], gt["full"]))
        candidates = visible_first.candidates(gt)
        if candidates and (gt["visible"][unrevealed] > 0).any() and (gt["visible"][unrevealed] == 0).any():
            assert gt["visible"][candidates[0][1][0]] > 0                    # a target the image shows
            least = PrivilegedPushPolicy(env, lookahead=1).candidates(gt)
            assert gt["visible"][least[0][1][0]] == 0                        # the reference: hidden ones first
            checked += 1
    assert checked >= 1
    with pytest.raises(ValueError, match="unknown target order"):
        PrivilegedPushPolicy(env, order="random")


def test_smoothed_push_target_spreads_over_nearby_allowed_starts_of_the_same_direction():
    from mqa_rl.losses.demonstration import smoothed_push_target

    demo = torch.tensor([actions.encode(3, 10, 12), actions.encode(0, 0, 0)])
    allowed = torch.ones(2, actions.NUM_ACTIONS, dtype=torch.bool)
    allowed[0, actions.encode(3, 10, 13)] = False
    target = smoothed_push_target(demo, allowed, sigma=1.0)
    assert torch.allclose(target.sum(-1), torch.ones(2))
    assert target[0].argmax() == demo[0] and target[0, actions.encode(3, 10, 13)] == 0
    assert target[0, actions.encode(3, 11, 12)] > 0.5 * target[0, demo[0]]         # one cell off: nearly as good
    assert target[0, actions.encode(3, 20, 12)] < 1e-6                               # across the bin: not
    assert target[0, actions.encode(2, 10, 12)] == 0 and target[:, actions.STOP].eq(0).all()
    torch.manual_seed(0)
    net = PushQNet(VOCAB, camera_distance=0.9, **SMALL)
    demos = _demos()
    loss = DemonstrationLoss(net, kind="push_cross_entropy", smooth_cells=1.0)
    first = loss(demos)["loss_demo"].item()
    td = _fit(net, loss, demos, 60)
    assert torch.isfinite(td["loss_demo"]) and td["loss_demo"].item() < first
    assert td["demo_near"].item() == 1.0
    with pytest.raises(ValueError, match="smooth_cells"):
        DemonstrationLoss(net, kind="push_cross_entropy", smooth_cells=-1)


def test_the_image_teacher_only_serves_targets_the_image_shows(small_dataset):
    from mqa_rl.modules.push.privileged_policy import PrivilegedPushPolicy

    served = 0
    for env, gt in _hard_scene_truths(small_dataset):
        policy = PrivilegedPushPolicy(env, lookahead=1, order="visible_first", geometry="visible")
        candidates = policy.candidates(gt)
        assert all(gt["visible"][t] > 0 for _, (t, _) in candidates)
        served += len(candidates)
        if not candidates:
            assert policy.choose() == actions.STOP
    assert served > 0


@pytest.mark.parametrize("reference,base", [("privileged_countable", "privileged"),
                                            ("countable_image_teacher", "image_teacher")])
def test_the_countable_references_serve_only_targets_below_the_counters_line(small_dataset, reference, base):
    """The systems ``privileged_countable`` and ``countable_image_teacher`` serve a target until it shows the perfect
    counter's 20 px, whatever share of its silhouette that is: a subset of what the oracle (the image teacher) serves."""
    from conftest import system_registry

    from mqa_rl.modules.frozen_policies import make_frozen_policy
    from mqa_rl.modules.systems import system_spec

    systems = system_registry()
    served = 0
    for env, gt in _hard_scene_truths(small_dataset):
        countable, _ = make_frozen_policy(system_spec(systems, reference), env, 10)
        mine = {t for _, (t, _) in countable.candidates(gt)}
        assert all(gt["target"][t] and gt["visible"][t] < countable.min_visible_px for t in mine)
        assert mine <= {t for _, (t, _) in make_frozen_policy(system_spec(systems, base), env, 10)[0].candidates(gt)}
        served += len(mine)
        if not mine:
            assert countable.choose() == actions.STOP
    assert served > 0


def test_stop_margin_teaches_when_the_demonstrator_stops():
    torch.manual_seed(0)
    net = PushQNet(VOCAB, camera_distance=0.9, **SMALL)
    demos = _demos()                                   # the third demonstration is a stop
    loss = DemonstrationLoss(net, kind="push_cross_entropy", smooth_cells=1.0, stop_margin=0.5)
    _fit(net, loss, demos, 80)
    assert loss(demos)["demo_stop_agreement"].item() == 1.0
    with torch.no_grad():
        q = net(demos[keys.RGB], demos[keys.DEPTH], demos[keys.QUESTION])
    best_push = q[:, : actions.NUM_PUSHES].masked_fill(~demos[keys.ACTION_MASK][:, : actions.NUM_PUSHES], -1e9).max(-1).values
    assert (q[:, actions.STOP] > best_push).tolist() == [False, False, True, False]
    assert DemonstrationLoss(net, kind="push_cross_entropy")(demos[2:3])["loss_demo"].item() == 0.0


def test_visible_geometry_oracle_reads_only_what_the_image_shows(small_dataset):
    """Its occluders border the target's visible pixels and stand higher there; the push runs from the
    target's visible centroid towards the occluder's (same direction bin as the candidate's)."""
    import math

    import numpy as np

    from mqa_rl.modules.push.privileged_policy import PrivilegedPushPolicy

    served = 0
    for env, gt in _hard_scene_truths(small_dataset):
        policy = PrivilegedPushPolicy(env, lookahead=1, order="visible_first", geometry="visible")
        seg, ids = gt["seg"], gt["entity_ids"]
        candidates = policy.candidates(gt)
        for i, (action, (t, j)) in enumerate(candidates):
            target, occluder = seg == ids[t], seg == ids[j]
            assert target.any() and occluder.any()
            ys, xs = np.nonzero(target)
            oy, ox = np.nonzero(occluder)
            gap = np.min(np.abs(ys[:, None] - oy[None]) + np.abs(xs[:, None] - ox[None]))
            assert gap <= 2 * policy.border_px
            v = np.array([ox.mean() + 0.5 - (xs.mean() + 0.5), oy.mean() - ys.mean()])
            if np.linalg.norm(v) < 2.0:                 # centred on each other: pushed outwards instead
                continue
            expected = int(round(math.degrees(math.atan2(-v[1], v[0])) / 45.0)) % actions.DIRECTIONS
            turn = (actions.decode(action)[0] - expected) % actions.DIRECTIONS
            assert turn in ((0,) if i == 0 else (0, 1, 7))   # straight away first, then ±45°
            served += 1
    assert served > 0
    with pytest.raises(ValueError, match="unknown oracle geometry"):
        PrivilegedPushPolicy(env, geometry="hidden")


def test_direction_term_scores_the_eight_directions_at_the_demonstrated_cell():
    """The direction cross-entropy reads exactly Q(d, start cell) for the 8 d, is 0 on stops, and training
    with it makes the demonstrated direction the best at its cell."""
    from mqa_rl.losses.demonstration import direction_cross_entropy

    q = torch.zeros(2, actions.NUM_ACTIONS)
    q[0, actions.encode(3, 5, 7)] = 4.0                 # the demonstrated push of state 0
    q[0, actions.encode(1, 5, 7)] = 2.0                 # another direction at the same cell
    q[0, actions.encode(6, 9, 9)] = 50.0                # another cell: not part of the term
    demo = torch.tensor([actions.encode(3, 5, 7), actions.STOP])
    expected = torch.nn.functional.cross_entropy(torch.tensor([[0, 2.0, 0, 4.0, 0, 0, 0, 0]]), torch.tensor([3]))
    assert torch.isclose(direction_cross_entropy(q, demo), expected)
    assert direction_cross_entropy(q[1:], demo[1:]).item() == 0.0

    torch.manual_seed(0)
    net = PushQNet(VOCAB, camera_distance=0.9, **SMALL)
    demos = _demos()
    plain = DemonstrationLoss(net, kind="push_cross_entropy")
    both = DemonstrationLoss(net, kind="push_cross_entropy", direction_weight=1.0)
    assert both(demos)["loss_demo"] > plain(demos)["loss_demo"]
    _fit(net, both, demos, 40)
    with torch.no_grad():
        q = net(demos[keys.RGB], demos[keys.DEPTH], demos[keys.QUESTION])
    per = actions.GRID ** 2
    pushes = demos[keys.ACTION][demos[keys.ACTION] != actions.STOP]
    at_cell = q[demos[keys.ACTION] != actions.STOP, : actions.NUM_PUSHES].view(-1, actions.DIRECTIONS, per)
    assert torch.equal(at_cell[torch.arange(len(pushes)), :, pushes % per].argmax(-1), pushes // per)
    with pytest.raises(ValueError, match="direction_weight"):
        DemonstrationLoss(net, kind="push_cross_entropy", direction_weight=-1.0)
