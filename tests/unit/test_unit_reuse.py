"""An evaluation reuses a finished unit only when everything it depends on is the same, by content: change any one
input (the dataset's files at the same path, the questions' settings, the reward, the kept-frame perception, greedy's
stop critic or videos) and the unit runs again."""

import io
import json

import pytest
import torch
from omegaconf import OmegaConf

from mqa_rl.evaluation.unit_reuse import content_digest, episodes_meta, reuse_episodes


def _cfg(**over):
    return OmegaConf.create({"split": "test", "seed": 123, "episodes_per_level": 4, "pusher": "finger", **over})


def _dataset(folder, seed):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "manifest.json").write_text(json.dumps({"seed": seed}))
    return folder


def _bank(folder, name, meta):
    buffer = io.BytesIO()
    torch.save({"meta": meta, "metrics": {"chi_end": torch.ones(4)}}, buffer)
    (folder / "episodes").mkdir(parents=True, exist_ok=True)
    (folder / "episodes" / f"{name}_{meta['level']}.pt").write_bytes(buffer.getvalue())


BASE = dict(level="easy", qtypes=["counting"], max_pushes=10, reward={"name": "global"}, push_memory=None)
CHANGES = {                                          # one input changed at a time
    "split": dict(cfg=dict(split="train")), "seed": dict(cfg=dict(seed=5)),
    "episodes": dict(cfg=dict(episodes_per_level=8)), "pusher": dict(cfg=dict(pusher="arm")),
    "question types": dict(qtypes=["existence"]), "push limit": dict(max_pushes=5),
    "push memory": dict(push_memory=1), "kept frame": dict(kept_frame="other perception digest"),
}


@pytest.mark.parametrize("change", sorted(CHANGES))
def test_changing_any_one_input_runs_the_unit_again(tmp_path, change):
    data = _dataset(tmp_path / "data", seed=0)
    base = {**BASE, "kept_frame": "perception digest"}
    meta = episodes_meta(_cfg(), data, base["level"], base["qtypes"], base["max_pushes"], base["reward"],
                         base["push_memory"], base["kept_frame"])
    _bank(tmp_path / "eval", "random_masked", meta)
    assert reuse_episodes(tmp_path / "eval", "random_masked", meta) is not None       # the same: reused
    args = {**base, **{k: v for k, v in CHANGES[change].items() if k != "cfg"}}
    other = episodes_meta(_cfg(**CHANGES[change].get("cfg", {})), data, args["level"], args["qtypes"], args["max_pushes"],
                          args["reward"], args["push_memory"], args["kept_frame"])
    assert reuse_episodes(tmp_path / "eval", "random_masked", other) is None


def test_a_dataset_regenerated_at_the_same_path_is_another_dataset(tmp_path):
    data = _dataset(tmp_path / "data", seed=0)
    meta = episodes_meta(_cfg(), data, **BASE)
    _bank(tmp_path / "eval", "random", meta)
    _dataset(tmp_path / "data", seed=1)                                                # overwritten in place
    assert reuse_episodes(tmp_path / "eval", "random", episodes_meta(_cfg(), data, **BASE)) is None


def test_a_changed_file_at_the_same_path_changes_its_digest_and_a_missing_one_is_named(tmp_path):
    stop = tmp_path / "stop"
    stop.mkdir()
    (stop / "stop_critic.pt").write_bytes(b"a")
    folder, file = content_digest(stop, "stop_critic", "stop_critic.pt"), content_digest(stop / "stop_critic.pt", "stop_critic")
    assert folder == file                              # the folder or the file itself: the same content, the same key
    (stop / "stop_critic.pt").write_bytes(b"b")
    assert content_digest(stop, "stop_critic", "stop_critic.pt") != folder
    assert content_digest(None, "kept_frame") is None
    with pytest.raises(FileNotFoundError, match="kept_frame=.*names no file"):
        content_digest(tmp_path / "nothing.pt", "kept_frame")
