"""The square's symmetries on transitions: the action index, the Q/mask maps and the images agree,
and they are the physical rotation / mirror of the push (start cell and direction); the two numberings
of the 8 (the replay's and the frame pipelines') name the same 8 symmetries."""

import math

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.replay import make_replay_buffer
from mqa_rl.envs import actions
from mqa_rl.envs.dihedral import (DIHEDRAL, DihedralAugment, dihedral, mirror_first, random_dihedral,
                                        transform_action, transform_images, transform_push_map)

ELEMENTS = [(k, m) for m in (False, True) for k in range(4)]


@pytest.mark.parametrize("k,mirror", ELEMENTS)
def test_action_index_and_map_agree(k, mirror):
    a = torch.tensor([0, 5, 783, 784 + 28 * 3 + 7, 6271, actions.STOP])
    onehot = torch.nn.functional.one_hot(a, actions.NUM_ACTIONS).float()
    moved = transform_push_map(onehot, k, mirror)
    assert moved.argmax(-1).tolist() == transform_action(a, k, mirror).tolist()
    assert transform_action(a, k, mirror)[-1] == actions.STOP


@pytest.mark.parametrize("k,mirror", ELEMENTS)
def test_the_push_turns_with_the_picture(k, mirror):
    """Start cell centre (about the image centre) and direction vector, in image coordinates
    (x right, y up), move by the same rotation / mirror as the image."""
    rng = np.random.default_rng(k + 4 * mirror)
    for _ in range(20):
        d, r, c = int(rng.integers(8)), int(rng.integers(28)), int(rng.integers(28))
        d2, r2, c2 = actions.decode(int(transform_action(torch.tensor(actions.encode(d, r, c)), k, mirror)))
        p = np.array([c - 13.5, 13.5 - r])                  # image x right, y up
        v = actions.direction_xy(d)
        if mirror:
            p, v = p * [-1, 1], v * [-1, 1]
        rot = np.array([[math.cos(k * math.pi / 2), -math.sin(k * math.pi / 2)],
                        [math.sin(k * math.pi / 2), math.cos(k * math.pi / 2)]])
        np.testing.assert_allclose(rot @ p, [c2 - 13.5, 13.5 - r2], atol=1e-9)
        np.testing.assert_allclose(rot @ v, actions.direction_xy(d2), atol=1e-9)
        # the image: a marked pixel block at the cell moves to the new cell
        img = torch.zeros(1, 224, 224)
        img[0, r * 8:(r + 1) * 8, c * 8:(c + 1) * 8] = 1
        out = transform_images(img, k, mirror)
        assert out[0, r2 * 8:(r2 + 1) * 8, c2 * 8:(c2 + 1) * 8].sum() == 64


def test_the_two_numberings_name_the_same_eight_symmetries():
    """The frames' ``dihedral(x, i)`` turns first, then mirrors: for i >= 4 that is the mirror followed by
    -i % 4 quarter turns, the replay's (k, mirror) form; both numberings cover all 8 symmetries once."""
    x = torch.arange(2 * 3 * 5 * 5).reshape(2, 3, 5, 5)
    for i in range(DIHEDRAL):
        turned = torch.rot90(x, i % 4, dims=(-2, -1))
        assert torch.equal(dihedral(x, i), turned.flip(-1) if i >= 4 else turned)
        assert torch.equal(dihedral(x, i), transform_images(x, (i, -i % 4)[i >= 4], i >= 4))
    frames = {tuple(dihedral(x, i).flatten().tolist()) for i in range(DIHEDRAL)}
    replay = {tuple(transform_images(x, *mirror_first(i)).flatten().tolist()) for i in range(DIHEDRAL)}
    assert len(frames) == DIHEDRAL and frames == replay


def test_the_augment_turns_a_sample_by_its_drawn_symmetry_in_the_replays_numbering():
    """``DihedralAugment`` draws g in [0, 8) per sample and applies ``mirror_first(g)`` to images, mask and action."""
    data = _batch(16)
    out = DihedralAugment(generator=torch.Generator().manual_seed(3)).forward(data.clone())
    picks = torch.randint(0, DIHEDRAL, (16,), generator=torch.Generator().manual_seed(3))
    for i, g in enumerate(picks.tolist()):
        k, mirror = mirror_first(g)
        assert torch.equal(out[keys.RGB][i], transform_images(data[keys.RGB][i], k, mirror))
        assert torch.equal(out["next", keys.DEPTH][i], transform_images(data["next", keys.DEPTH][i], k, mirror))
        assert torch.equal(out[keys.ACTION_MASK][i], transform_push_map(data[keys.ACTION_MASK][i], k, mirror))
        assert out[keys.ACTION][i] == transform_action(data[keys.ACTION][i], k, mirror)


def _batch(n=32):
    g = torch.Generator().manual_seed(0)
    obs = lambda: {keys.RGB: torch.randint(0, 255, (n, 3, 16, 16), dtype=torch.uint8, generator=g),
                   keys.DEPTH: torch.rand(n, 1, 16, 16, generator=g).half(),
                   keys.QUESTION: torch.randint(1, 9, (n, 5), generator=g),
                   keys.ACTION_MASK: torch.rand(n, actions.NUM_ACTIONS, generator=g) > 0.3}
    td = TensorDict({**obs(), keys.ACTION: torch.randint(0, actions.NUM_ACTIONS, (n,), generator=g),
                     "next": {**obs(), keys.REWARD: torch.rand(n, 1, generator=g), "done": torch.zeros(n, 1, dtype=torch.bool)}},
                    batch_size=[n])
    td[keys.ACTION_MASK][torch.arange(n), td[keys.ACTION]] = True
    return td


def test_replay_samples_come_out_turned_and_consistent(tmp_path):
    rb = make_replay_buffer({"size": 64, "batch_size": 32, "alpha": 0.3, "storage": "memory", "augment": "dihedral"}, None)
    data = _batch()
    rb.extend(data.clone())
    s = rb.sample()
    src = data[s["index"]]
    changed = (s[keys.ACTION] != src[keys.ACTION])
    assert changed.any()                                        # some samples turned
    assert s[keys.ACTION_MASK].gather(-1, s[keys.ACTION][:, None]).all()   # the taken push stays allowed
    torch.testing.assert_close(s["next", keys.REWARD], src["next", keys.REWARD])
    torch.testing.assert_close(s[keys.QUESTION], src[keys.QUESTION])
    assert s[keys.ACTION_MASK].sum(-1).tolist() == src[keys.ACTION_MASK].sum(-1).tolist()
    # stored data untouched (the transform works on the sample)
    torch.testing.assert_close(rb.storage.get(s["index"])[keys.RGB], src[keys.RGB])
    rb.update_tensordict_priority(s.set(keys.TD_ERROR, torch.rand(32)))      # priorities still update


def test_unknown_augment_is_refused():
    with pytest.raises(ValueError, match="augment"):
        make_replay_buffer({"size": 8, "batch_size": 4, "storage": "memory", "augment": "flip"}, None)


def test_random_dihedral_turns_every_image_of_a_frame_by_the_same_drawn_symmetry():
    torch.manual_seed(0)
    rgb = torch.randint(0, 255, (64, 3, 6, 6), dtype=torch.uint8)
    labels = rgb[:, 0].clone()                       # a label map that is a function of the pixels it labels
    out_rgb, out_labels = random_dihedral(rgb, labels)
    assert torch.equal(out_labels, out_rgb[:, 0])    # image and labels turned alike, frame by frame
    drawn = [next(t for t in range(DIHEDRAL) if torch.equal(dihedral(rgb[i], t), out_rgb[i])) for i in range(64)]
    assert len(set(drawn)) > 4                       # frames draw their own symmetries
    assert torch.equal(labels, rgb[:, 0])            # the inputs are left as they were
