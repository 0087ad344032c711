"""Files a user is handed (a results folder, a cache of trajectories) are read as tensors and plain
containers only: a file holding a pickled object is refused, naming the file, and its code never runs."""

import pytest
import torch
from conftest import load_recipe

from mqa_rl.files import load_tensors

RAN = []


class Payload:
    """Unpickling it would call ``record`` (what a crafted file's code would do)."""

    def __reduce__(self):
        return (RAN.append, ("code ran",))


def test_load_tensors_refuses_pickled_objects_and_reads_plain_results(tmp_path):
    torch.save({"meta": {"level": "easy", "episodes": 3, "types": ["counting"], "none": None},
                "metrics": {"reward": torch.ones(3)}}, tmp_path / "plain.pt")
    assert load_tensors(tmp_path / "plain.pt", what="results file", hint="h")["meta"]["episodes"] == 3
    torch.save({"meta": Payload()}, tmp_path / "crafted.pt")
    with pytest.raises(ValueError, match="crafted.pt.*never unpickled"):
        load_tensors(tmp_path / "crafted.pt", what="results file", hint="delete it")
    assert RAN == []


def test_evaluate_policy_baselines_and_fit_stop_caches_are_not_unpickled(tmp_path):
    evaluate_policy = load_recipe("evaluate_policy")
    (tmp_path / "episodes").mkdir()
    torch.save({"meta": Payload(), "metrics": {}}, tmp_path / "episodes" / "random_easy.pt")
    with pytest.raises(ValueError, match="random_easy.pt.*never unpickled"):
        evaluate_policy.reuse_baseline(tmp_path, "random", {"level": "easy"})
    assert RAN == []
    fit_stop = load_recipe("fit_stop")
    torch.save({"meta": Payload(), "data": {}}, tmp_path / "easy.pt")
    with pytest.raises(ValueError, match="easy.pt.*never unpickled"):
        fit_stop.cached_trajectories(tmp_path / "easy.pt", {"level": "easy"})
    torch.save({"meta": {"level": "easy"}, "data": {"chi": torch.zeros(2)}}, tmp_path / "plain.pt")
    assert fit_stop.cached_trajectories(tmp_path / "plain.pt", {"level": "easy"})["chi"].shape == (2,)
    assert fit_stop.cached_trajectories(tmp_path / "plain.pt", {"level": "hard"}) is None
    assert RAN == []
