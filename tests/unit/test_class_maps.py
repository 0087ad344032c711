"""benchmarks/class_maps.py: a class map scored against the simulator's class fractions per push-grid cell."""

import importlib.util
from pathlib import Path

import pytest
import torch

REPO = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("class_maps", REPO / "benchmarks" / "class_maps.py")
class_maps = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(class_maps)


def _truth() -> torch.Tensor:
    """[3, 4, 4]: bin everywhere but class 1 in the top-left 2 × 2 cells and class 2 in the bottom row."""
    t = torch.zeros(3, 4, 4)
    t[0] = 1.0
    t[:, :2, :2] = torch.tensor([0.0, 1.0, 0.0])[:, None, None]
    t[:, 3, :] = torch.tensor([0.0, 0.0, 1.0])[:, None]
    return t


def test_the_truth_scores_perfectly_and_a_swapped_class_loses_its_cells_and_regions():
    truth = _truth()
    assert class_maps.scores(truth, truth) == pytest.approx((1.0, 1.0, 0.0))
    swapped = truth.clone()
    swapped[[1, 2], :2, :2] = swapped[[2, 1], :2, :2]              # class 1's cells read as class 2
    right, iou, l1 = class_maps.scores(swapped, truth)
    assert right == pytest.approx(4 / 8)                            # the bottom row's 4 of the 8 object cells
    assert iou == pytest.approx((0.0 + 4 / 8) / 2)                  # class 1 found nowhere; class 2's region doubled
    assert l1 == pytest.approx(2.0 * 4 / 8)                         # 2 of fraction error on half the object cells
