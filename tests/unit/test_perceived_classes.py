"""The push policy reading the counting perception's class map (``model.perceived_classes``)."""

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import Categorical

from mqa_rl import keys
from mqa_rl.collectors.replay import compact_transitions
from mqa_rl.envs import actions
from mqa_rl.modules.perceived_classes import PerceivedClasses
from mqa_rl.modules.perception import CountingPerception, save_perception
from mqa_rl.modules.push_policy import PerceivingActor, make_push_qnet, make_q_actor, perceiver_of
from mqa_rl.transforms.dihedral import DihedralAugment, mirror_first, transform_images
from torch_threads import one_torch_thread  # noqa: F401  (autouse)

VOCAB, S, CLASSES = 30, 224, 4
MODEL = dict(class_map=True, rotated_head=True, geometric_push=True, light_channels=[8, 8, 16, 16], light_downsample=2,
             fuse_channels=[16, 8], head_channels=[8, 8], head_context=1)


def _perception(tmp_path, classes=CLASSES):
    torch.manual_seed(0)
    return save_perception(CountingPerception(1 + classes, widths=(8, 8, 16, 16)), tmp_path / f"perception{classes}.pt", {})


def _actor(tmp_path, **kw):
    torch.manual_seed(1)
    path = _perception(tmp_path)
    net = make_push_qnet({**MODEL, "perceived_classes": str(path), **kw}, vocab_size=VOCAB, camera_distance=0.9,
                         num_classes=CLASSES).eval()
    return make_q_actor(net, Categorical(actions.NUM_ACTIONS), perceived_classes=path), net, path


def _states(batch=2, seed=0):
    g = torch.Generator().manual_seed(seed)
    return TensorDict({keys.RGB: torch.randint(0, 256, (batch, 3, S, S), dtype=torch.uint8, generator=g),
                       keys.DEPTH: 0.8 + 0.1 * torch.rand(batch, 1, S, S, generator=g),
                       keys.QUESTION: torch.randint(1, VOCAB, (batch, 6), generator=g),
                       keys.ACTION_MASK: torch.ones(batch, actions.NUM_ACTIONS, dtype=torch.bool)}, batch_size=[batch])


def test_the_actor_reads_the_perceptions_class_map_on_the_push_grid_and_not_its_class_head(tmp_path):
    actor, net, _ = _actor(tmp_path)
    assert isinstance(actor, PerceivingActor) and keys.PERCEIVED_CLASSES in actor.in_keys
    td = actor(_states())
    classes = td.get(keys.PERCEIVED_CLASSES)
    assert classes.shape == (2, 1 + CLASSES, actions.GRID, actions.GRID)
    torch.testing.assert_close(classes.sum(1), torch.ones(2, actions.GRID, actions.GRID))     # probabilities per cell
    before = td.get(keys.ACTION_VALUE).clone()
    with torch.no_grad():
        net.class_head.bias.add_(torch.randn(1 + CLASSES))             # the class head plays no part
        again = actor(_states()).get(keys.ACTION_VALUE)
        torch.testing.assert_close(again, before)
        changed = _states().set(keys.PERCEIVED_CLASSES, classes.roll(1, dims=1))    # another class map: other values
        assert not torch.allclose(actor(changed).get(keys.ACTION_VALUE), before)


def test_stored_perceived_classes_are_reused_and_a_network_that_needs_them_says_so(tmp_path):
    actor, net, _ = _actor(tmp_path)
    td = _states().set(keys.PERCEIVED_CLASSES, torch.full((2, 1 + CLASSES, actions.GRID, actions.GRID), 0.2))
    assert torch.equal(actor(td).get(keys.PERCEIVED_CLASSES), torch.full_like(td.get(keys.PERCEIVED_CLASSES), 0.2))
    s = _states()
    with pytest.raises(ValueError, match="reads the perceived classes"):
        net(s.get(keys.RGB), s.get(keys.DEPTH), s.get(keys.QUESTION))


def test_the_actor_and_the_network_must_agree_on_the_perception_and_its_classes(tmp_path):
    _, net, path = _actor(tmp_path)
    with pytest.raises(ValueError, match="give make_q_actor the counting perception"):
        make_q_actor(net, Categorical(actions.NUM_ACTIONS))
    plain = make_push_qnet(MODEL, vocab_size=VOCAB, camera_distance=0.9, num_classes=CLASSES)
    with pytest.raises(ValueError, match="reads its own class head"):
        make_q_actor(plain, Categorical(actions.NUM_ACTIONS), perceived_classes=path)
    assert perceiver_of(make_q_actor(plain, Categorical(actions.NUM_ACTIONS))) is None
    with pytest.raises(ValueError, match="tells 6 object classes and the dataset has 4"):
        PerceivedClasses.from_file(_perception(tmp_path, classes=6), CLASSES)
    with pytest.raises(ValueError, match="needs class_map=true"):
        make_push_qnet({"perceived_classes": str(path)}, vocab_size=VOCAB, camera_distance=0.9, num_classes=CLASSES)


def test_the_replay_keeps_both_states_perceived_classes_and_the_augment_turns_them(tmp_path):
    actor, _, _ = _actor(tmp_path)
    data = actor(_states())
    data.set("next", _states(seed=1).update({keys.REWARD: torch.zeros(2, 1), "done": torch.zeros(2, 1, dtype=torch.bool),
                                            "terminated": torch.zeros(2, 1, dtype=torch.bool),
                                            "truncated": torch.zeros(2, 1, dtype=torch.bool)}))
    data.set(keys.TARGET_CELLS, torch.zeros(2, actions.GRID, actions.GRID))
    perceiver_of(actor).fill(data)                                      # the successors' read once
    stored = compact_transitions(data)
    for key in (keys.PERCEIVED_CLASSES, ("next", keys.PERCEIVED_CLASSES)):
        assert stored.get(key).dtype == torch.float16
        torch.testing.assert_close(stored.get(key).float(), data.get(key), atol=1e-3, rtol=0)
    picks = torch.randint(0, 8, (2,), generator=torch.Generator().manual_seed(3))       # what the augment draws
    turned = DihedralAugment(generator=torch.Generator().manual_seed(3)).forward(stored.clone())
    for i, pick in enumerate(picks.tolist()):
        k, mirror = mirror_first(pick)
        for key in (keys.PERCEIVED_CLASSES, ("next", keys.PERCEIVED_CLASSES)):
            assert torch.equal(turned.get(key)[i], transform_images(stored.get(key)[i], k, mirror))


def test_a_successor_that_is_the_next_transitions_root_takes_its_reading_and_is_not_read_again(tmp_path):
    actor, _, _ = _actor(tmp_path)
    perceiver = perceiver_of(actor)
    roots = _states(batch=3)
    after = _states(batch=3, seed=1)
    after.get(keys.RGB)[0] = roots.get(keys.RGB)[1]                    # transition 0 leads to transition 1's state
    data = roots.clone().set("next", after)
    actor(data)                                                          # the acting policy reads the roots
    frames_read = []
    predict = perceiver.perception.predict
    perceiver.perception.predict = lambda rgb, *a: (frames_read.append(len(rgb)), predict(rgb, *a))[1]
    perceiver.fill(data)
    assert sum(frames_read) == 2                                         # successors 1 and 2; 0 reused
    expected = PerceivedClasses(perceiver.perception).read(after.get(keys.RGB))
    torch.testing.assert_close(data.get(("next", keys.PERCEIVED_CLASSES)), expected, atol=1e-5, rtol=0)


def test_a_demonstration_folders_readings_are_kept_beside_it_and_read_from_there_the_next_time(tmp_path):
    actor, _, _ = _actor(tmp_path)
    perceiver = perceiver_of(actor)
    frames_read = []
    predict = perceiver.perception.predict
    perceiver.perception.predict = lambda rgb, *a: (frames_read.append(len(rgb)), predict(rgb, *a))[1]
    folder = tmp_path / "demos"
    first = perceiver.kept(_states(batch=3), folder)
    kept = sorted(folder.glob("perceived_classes-*.pt"))
    assert len(kept) == 1 and sum(frames_read) == 3
    again = perceiver.kept(_states(batch=3), folder)                   # the next phase of a chain: not read again
    assert sum(frames_read) == 3
    assert torch.equal(again.get(keys.PERCEIVED_CLASSES), first.get(keys.PERCEIVED_CLASSES))
    kept[0].write_bytes(b"half a file")                                 # unreadable, or of another length: read again
    perceiver.kept(_states(batch=3), folder)
    perceiver.kept(_states(batch=4), folder)
    assert sum(frames_read) == 3 + 3 + 4
