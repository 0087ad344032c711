"""Files a user is handed (a results folder, a cache of trajectories, rollout chunks, demonstrations) are read
as tensors, plain containers and JSON only: a file holding a pickled object is refused, naming the file, and its
code never runs. (Checkpoints: tests/unit/test_training_checkpoint.py.)"""

import pytest
import torch
from conftest import load_recipe

from mqa_rl.evaluation.unit_reuse import reuse_episodes
from mqa_rl.files import load_tensors
from mqa_rl.training.stop_trajectories import cached_trajectories, save_trajectories

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
    (tmp_path / "episodes").mkdir()
    torch.save({"meta": Payload(), "metrics": {}}, tmp_path / "episodes" / "random_easy.pt")
    with pytest.raises(ValueError, match="random_easy.pt.*never unpickled"):
        reuse_episodes(tmp_path, "random", {"level": "easy"})
    assert RAN == []
    torch.save({"meta": Payload(), "data": {}}, tmp_path / "easy.pt")
    with pytest.raises(ValueError, match="easy.pt.*never unpickled"):
        cached_trajectories(tmp_path / "easy.pt", {"level": "easy"})
    save_trajectories(tmp_path / "plain.pt", {"level": "easy"}, {"chi": torch.zeros(2)})
    assert cached_trajectories(tmp_path / "plain.pt", {"level": "easy"})["chi"].shape == (2,)
    assert cached_trajectories(tmp_path / "plain.pt", {"level": "hard"}) is None
    assert RAN == []


def test_memmap_folders_with_a_pickled_leaf_are_refused(tmp_path):
    """A rollout chunk or a demonstrations folder is a memmap TensorDict: a pickled leaf (TensorDict writes
    non-tensor objects to other.pickle) is refused by every reader, before anything is unpickled."""
    import json
    import pickle

    from tensordict import TensorDict

    from mqa_rl import keys
    from mqa_rl.collectors.demonstrations import DEMOS_META, load_demonstrations
    from mqa_rl.collectors.store import load_records
    from mqa_rl.files import PickledFileRefused

    store = tmp_path / "rollouts"
    TensorDict({keys.SLOT: torch.arange(3)}, batch_size=[3]).memmap(prefix=str(store / "chunk-00000"))
    (store / "meta.json").write_text(json.dumps({"plan": {"slots": 3}}))
    (store / "chunk-00000" / "other.pickle").write_bytes(pickle.dumps(Payload()))
    with pytest.raises(PickledFileRefused, match="chunk-00000/other.pickle.*never unpickled.*delete that chunk"):
        load_records(store, None, require_complete=False)
    demos = tmp_path / "demos"
    TensorDict({keys.SLOT: torch.arange(2)}, batch_size=[2]).memmap(prefix=str(demos / "data"))
    (demos / DEMOS_META).write_text(json.dumps({"states": 2}))
    (demos / "data" / "nested").mkdir()
    (demos / "data" / "nested" / "other.pickle").write_bytes(pickle.dumps(Payload()))
    with pytest.raises(ValueError, match="nested/other.pickle.*never unpickled"):
        load_demonstrations(demos)
    assert RAN == []


class _RecognitionNet:
    class_head = object()          # what load_recognition checks before it reads the file


@pytest.mark.parametrize("loader", ["stop critic", "VQA", "perception", "VQA encoder", "recognition"])
def test_every_model_file_loader_refuses_a_pickled_payload(tmp_path, loader):
    """The model files a user is handed (a stop critic, a VQA, the perception, an encoder, a recognition file), each
    with a payload beside plausible keys: refused with ValueError naming the file, the payload never unpickled."""
    from mqa_rl.modules.answering.perception import load_perception
    from mqa_rl.modules.answering.vqa import load_vqa
    from mqa_rl.modules.answering.vqa_encoder import load_encoder
    from mqa_rl.modules.push.pretrained_recognition import load_recognition
    from mqa_rl.modules.stop.learned_stop import StopCritic

    path = tmp_path / "crafted.pt"
    torch.save({"format": "anything", "version": 1, "state_dict": {}, "meta": Payload()}, path)
    load = {"stop critic": StopCritic.load, "VQA": load_vqa, "perception": load_perception, "VQA encoder": load_encoder,
            "recognition": lambda p: load_recognition(_RecognitionNet(), p, [])}[loader]
    with pytest.raises(ValueError, match="crafted.pt"):
        load(path)
    assert RAN == []


def test_evaluate_policy_reuses_no_baseline_that_lacks_the_kept_frame_metrics(tmp_path):
    """A random unit banked by an evaluation without kept_frame= has no counter_kept: a kept-frame evaluation runs it
    again rather than report NaN for it."""
    evaluate_policy = load_recipe("evaluate_policy")
    (tmp_path / "episodes").mkdir()
    meta = {"level": "easy", "episodes": 2, "reward": {}}
    plain = {"counter_stop": torch.ones(2)}
    torch.save({"meta": meta, "metrics": plain}, tmp_path / "episodes" / "random_easy.pt")
    assert evaluate_policy.reuse_episodes(tmp_path, "random", meta)["counter_stop"].tolist() == [1.0, 1.0]
    assert evaluate_policy.reuse_episodes(tmp_path, "random", meta, evaluate_policy.KEPT_REPORTED) is None
    kept = {**plain, **{k: torch.zeros(2) for k in evaluate_policy.KEPT_REPORTED}}
    torch.save({"meta": meta, "metrics": kept}, tmp_path / "episodes" / "random_easy.pt")
    assert evaluate_policy.reuse_episodes(tmp_path, "random", meta, evaluate_policy.KEPT_REPORTED) is not None
