import numpy as np
import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.modules.answering.perception import CountingPerception
from mqa_rl.training.perception_maps import TILE, class_palette, perception_maps


def test_palette_keeps_the_bin_black_and_every_class_apart():
    palette = class_palette(21)
    assert palette.shape == (21, 3) and palette.dtype == np.uint8
    assert (palette[0] == 0).all() and len({tuple(c) for c in palette}) == 21


def test_maps_show_a_row_per_frame_and_leave_the_model_as_it_was():
    torch.manual_seed(0)
    model = CountingPerception(5, (8, 8, 16, 16), image_size=32).train()
    frames = TensorDict({keys.RGB: torch.randint(0, 256, (6, 3, 32, 32), dtype=torch.uint8)}, batch_size=[6])
    image = perception_maps(model, frames, torch.device("cpu"), count=4)
    assert image.shape == (4 * TILE, 3 * TILE, 3) and image.dtype == np.uint8
    assert model.training                                     # evaluated in eval mode, handed back training
    rows = image.reshape(4, TILE, 3 * TILE, 3)
    assert not np.array_equal(rows[0], rows[1])               # each row its own frame
