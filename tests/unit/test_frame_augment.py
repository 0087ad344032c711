"""Copy-paste on labelled frames keeps the counting labels true: a covered object loses exactly the pixels it
lost, a pasted one shows its donor's, and the counter's rule is re-read from the edited map."""

import pytest
import torch

from mqa_rl.training.frame_augment import copy_paste, dihedral_pair


def two_frames():
    """Two 8 × 8 frames at render size (area = pixels): frame 0 holds object slot 0 (class 3) on a 4 × 4
    square; frame 1 holds slot 0 (class 5) on a 2 × 8 strip across that square, slot 1 (class 7) elsewhere."""
    omap = torch.zeros(2, 8, 8, dtype=torch.uint8)
    omap[0, 2:6, 2:6] = 1
    omap[1, 3:5, :] = 1
    omap[1, 7, 7] = 2
    rgb = torch.zeros(2, 3, 8, 8, dtype=torch.uint8)
    rgb[0][:, omap[0] == 1] = 10
    rgb[1][:, omap[1] == 1] = 200
    rgb[1][:, omap[1] == 2] = 99
    classes = torch.zeros(2, 4, dtype=torch.int64)
    classes[0, 0], classes[1, 0], classes[1, 1] = 3, 5, 7
    visible = (torch.stack([torch.bincount(m.flatten().long(), minlength=5)[1:] for m in omap])).float()
    return rgb, omap, classes, visible


def test_pasting_rereads_visible_areas():
    rgb, omap, classes, visible = two_frames()
    g = torch.Generator().manual_seed(0)
    new_rgb, new_omap, new_cls, new_vis = copy_paste(rgb, omap, classes, visible, prob=1.0, max_objects=2, generator=g)
    for i in range(2):                   # the areas are the edited map's pixel counts, slot by slot
        counts = torch.bincount(new_omap[i].flatten().long(), minlength=5)[1:].float()
        shown = counts > 0
        assert torch.equal(new_vis[i][shown], counts[shown])
        assert (new_cls[i][shown] > 0).all()
    # frame 0 got at least the strip or the dot of frame 1 over it: its square lost what was covered
    assert new_vis[0, 0] <= 16 and (new_cls[0, 1:] > 0).any()
    pasted = new_omap[0] > 1
    assert torch.equal(new_rgb[0][:, pasted], rgb[1][:, pasted])
    assert torch.equal(rgb, two_frames()[0]) and torch.equal(visible, two_frames()[3])      # inputs untouched


def test_strip_over_square_halves_it():
    rgb, omap, classes, visible = two_frames()
    for seed in range(20):               # find a draw that pastes the strip (slot 0 of frame 1) onto frame 0
        out = copy_paste(rgb, omap, classes, visible, prob=1.0, max_objects=1, generator=torch.Generator().manual_seed(seed))
        if (out[2][0] == 5).any():
            assert out[3][0, 0] == 16 - 8 and out[3][0][out[2][0] == 5].item() == 16
            return
    pytest.fail("no draw pasted the strip")


def test_no_free_slot_means_no_paste_and_bad_settings_refused():
    rgb, omap, classes, visible = two_frames()
    full = classes.clone()
    full[full == 0] = 1
    out = copy_paste(rgb, omap, full, visible, prob=1.0, max_objects=3)
    assert torch.equal(out[1], omap)
    with pytest.raises(ValueError, match="prob in"):
        copy_paste(rgb, omap, classes, visible, prob=1.5, max_objects=1)


def test_dihedral_pair_moves_rgb_and_map_together():
    rgb, omap, _, _ = two_frames()
    r, m = dihedral_pair(rgb, omap)
    for i in range(2):
        assert torch.equal(r[i][0][m[i] > 0].unique(), rgb[i][0][omap[i] > 0].unique())
