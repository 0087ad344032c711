"""The countable chain's options refuse what cannot work, before anything runs: the countable teacher's gain check
needs simulated previews, and a stop can minimise only the measures its trajectories keep."""

import pytest
import torch

from mqa_rl import keys
from mqa_rl.modules.push.privileged_policy import PrivilegedPushPolicy
from mqa_rl.transforms.episode_stats import uncountable_share
from conftest import compose_recipe_config, load_recipe


def test_require_gain_needs_previews():
    with pytest.raises(ValueError, match="needs previews"):
        PrivilegedPushPolicy(None, lookahead=1, require_gain=True)     # no previews, no refinement: nothing to compare
    PrivilegedPushPolicy(None, lookahead=1, require_gain=True, refine_radius=1)


def test_fit_stop_refuses_an_unknown_value(tmp_path):
    fit_stop = load_recipe("fit_stop")
    cfg = compose_recipe_config("fit_stop", ["run=checkpoints/dqn_geometric_student", f"out_dir={tmp_path / 's'}",
                                             "value=countable"])
    with pytest.raises(ValueError, match=r"value='countable'.*\['chi', 'uncountable'\]"):
        fit_stop.main(cfg)
    assert not (tmp_path / "s").exists()


def test_uncountable_share_counts_targets_below_the_counters_line():
    from tensordict import TensorDict

    td = TensorDict({keys.TARGET_MASK: torch.tensor([[True, True, False, True], [False] * 4]),
                     keys.VISIBLE_AREA: torch.tensor([[25.0, 19.0, 0.0, 0.0], [50.0, 0.0, 0.0, 0.0]])}, batch_size=[2])
    assert uncountable_share(td).tolist() == pytest.approx([2 / 3, 0.0])
