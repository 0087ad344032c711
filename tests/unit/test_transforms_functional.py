"""The reward formulas (and the overlap rate χ the env measures) by hand, their degenerate cases, and properties."""

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from mqa_rl.envs.measurements import overlap_rate
from mqa_rl.transforms.functional import (
    beta_schedule,
    exploration_reward,
    global_occlusion_reward,
    is_simple_scene,
    local_occlusion_reward,
)

T = torch.tensor


def test_overlap_rate():
    assert torch.allclose(overlap_rate(T([50.0, 100.0, 0.0, 10.0]), T([100.0, 100.0, 0.0, 0.0])), T([0.5, 0.0, 1.0, 1.0]))
    assert overlap_rate(T([120.0]), T([100.0])).item() == 0.0          # rounding: A_s > A_t clips to 0


def test_exploration_by_hand():
    p0 = torch.zeros(3, 3)
    p1 = T([[0.06, 0, 0], [0, 0.03, 0], [9.0, 0, 0]])
    mask = T([True, True, False])                                    # the 9 m jump is padding
    assert exploration_reward(p0, p1, mask, 0.12).item() == pytest.approx(0.5)
    mask = T([True, True, True])                                     # 75 ≥ cap 4: ignored as a glitch
    assert exploration_reward(p0, p1, mask, 0.12).item() == pytest.approx(0.5)
    assert exploration_reward(p0, p1, mask, 0.12, cap=None).item() == pytest.approx(75.0)
    # the paper's s_i = |p_i|: per-object scale
    q0 = T([[0.1, 0, 0], [0.2, 0, 0]])
    q1 = T([[0.15, 0, 0], [0.2, 0.01, 0]])
    assert exploration_reward(q0, q1, T([True, True]), q0.norm(dim=-1)).item() == pytest.approx(0.5)
    assert exploration_reward(q0, q1, T([False, False]), 0.1).item() == 0.0


def test_global_and_local_by_hand():
    chi0 = T([0.8, 0.4, 0.9, 0.0])
    chi1 = T([0.2, 0.4, 0.1, 0.0])
    tgt = T([True, True, False, False])
    # χ_a = 0.6 → 0.3: R_g = 0.5; max χ 0.8 → 0.4: R_l = 0.5; min χ 0.4 → 0.2: 0.5
    assert global_occlusion_reward(chi0, chi1, tgt).item() == pytest.approx(0.5)
    assert local_occlusion_reward(chi0, chi1, tgt).item() == pytest.approx(0.5)
    assert local_occlusion_reward(chi0, chi1, tgt, "min").item() == pytest.approx(0.5)
    worse = T([0.9, 0.8, 0.0, 0.0])                                  # targets got more hidden
    assert global_occlusion_reward(chi0, worse, tgt).item() == pytest.approx((0.6 - 0.85) / 0.6)
    with pytest.raises(ValueError, match="reduce"):
        local_occlusion_reward(chi0, chi1, tgt, "mean")


def test_degenerate_cases_are_zero_not_nan():
    chi0, chi1 = T([0.5, 0.5]), T([0.1, 0.9])
    none = T([False, False])
    assert global_occlusion_reward(chi0, chi1, none).item() == 0.0    # m = 0
    assert local_occlusion_reward(chi0, chi1, none).item() == 0.0
    visible = T([0.0, 0.3])
    tgt = T([True, False])
    assert global_occlusion_reward(visible, chi1, tgt).item() == 0.0  # χ_a = 0: nothing to reveal
    assert local_occlusion_reward(visible, chi1, tgt).item() == 0.0
    assert local_occlusion_reward(visible, chi1, tgt, "min").item() == 0.0
    tiny = T([1e-45, 0.3])                                             # subnormal χ: no inf (found by hypothesis)
    assert global_occlusion_reward(tiny, chi1, tgt).item() == 0.0
    assert local_occlusion_reward(tiny, chi1, tgt).item() == 0.0


def test_batch_dims():
    chi0 = torch.rand(4, 5, 50)
    chi1 = torch.rand(4, 5, 50)
    tgt = torch.rand(4, 5, 50) > 0.7
    r = global_occlusion_reward(chi0, chi1, tgt)
    assert r.shape == (4, 5)
    assert torch.allclose(r[2, 3], global_occlusion_reward(chi0[2, 3], chi1[2, 3], tgt[2, 3]))
    assert local_occlusion_reward(chi0, chi1, tgt).shape == (4, 5)
    p = torch.rand(4, 5, 50, 3)
    assert exploration_reward(p, p + 0.01, tgt, 0.12).shape == (4, 5)
    assert is_simple_scene(chi0, tgt).shape == (4, 5)


def test_beta_schedule():
    assert beta_schedule(0, 2000).item() == 1.0
    assert beta_schedule(1000, 2000).item() == pytest.approx(0.75)
    assert beta_schedule(2000, 2000).item() == pytest.approx(0.5)
    assert beta_schedule(10**6, 2000).item() == pytest.approx(0.5)
    with pytest.raises(ValueError, match="positive"):
        beta_schedule(0, 0)


def test_simple_scene():
    tgt = T([True, True, False])
    assert is_simple_scene(T([0.1, 0.2, 0.9]), tgt).item()
    assert not is_simple_scene(T([0.1, 0.25, 0.0]), tgt).item()
    assert not is_simple_scene(T([0.1, 0.15, 0.0]), tgt, threshold=0.1).item()
    assert is_simple_scene(T([0.9, 0.9, 0.9]), T([False, False, False])).item()   # no target


chis = st.lists(st.floats(0, 1), min_size=1, max_size=20)


@settings(max_examples=200, deadline=None)
@given(chis, chis, st.lists(st.booleans(), min_size=1, max_size=20))
def test_properties(a, b, m):
    n = min(len(a), len(b), len(m))
    chi0, chi1, tgt = T(a[:n]), T(b[:n]), T(m[:n])
    for r in (global_occlusion_reward(chi0, chi1, tgt), local_occlusion_reward(chi0, chi1, tgt),
              local_occlusion_reward(chi0, chi1, tgt, "min")):
        assert torch.isfinite(r).all() and r.item() <= 1.0 + 1e-6


@given(st.integers(0, 10**7), st.integers(1, 10**6))
def test_beta_range(step, horizon):
    b = beta_schedule(step, horizon).item()
    assert 0.5 <= b <= 1.0


def test_beta_schedule_final_value():
    """β_T = 0 hands the reward to R_q after T; β_T = 1 keeps R_e alone; out of [0, 1] is refused."""
    assert beta_schedule(1000, 2000, final=0.0).item() == pytest.approx(0.5)
    assert beta_schedule(5000, 2000, final=0.0).item() == 0.0
    assert beta_schedule(5000, 2000, final=1.0).item() == 1.0
    with pytest.raises(ValueError, match="final β"):
        beta_schedule(0, 2000, final=1.5)
