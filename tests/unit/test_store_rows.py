"""Reading part of a store: ``rows`` picks records in slot order without a second copy of the rest."""

import pytest
import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.frame_records import load_frames
from mqa_rl.collectors.store import EpisodeStore, load_records


def _store(root, slots, scene_base=0, dataset=None):
    meta = {"slots": 12, "plan": {"size": 8}, **({"dataset": {"manifest_sha256": dataset}} if dataset else {})}
    with EpisodeStore(root, meta) as store:
        for chunk in slots:                                    # chunks written out of slot order
            s = torch.tensor(chunk)
            store.append(TensorDict({keys.SLOT: s, keys.SCENE: s // 3 + scene_base,
                                     keys.RGB: (s[:, None, None, None] * torch.ones(1, 8, 8, 3)).to(torch.uint8),
                                     "nested": {"x": s.float() * 0.5}}, batch_size=[len(chunk)]))
    return root


def test_rows_equal_indexing_the_whole_store(tmp_path):
    root = _store(tmp_path / "a", [[5, 6, 7, 8], [0, 1, 2, 3, 4], [9, 10, 11]])
    whole = load_records(root)
    assert whole.get(keys.SLOT).tolist() == list(range(12))
    rows = torch.tensor([1, 0, 0, 1, 1, 0, 1, 0, 1, 1, 0, 1], dtype=torch.bool)
    part = load_records(root, [keys.RGB, "nested"], rows=rows)
    assert part.get(keys.SLOT).tolist() == whole.get(keys.SLOT)[rows].tolist()
    assert torch.equal(part.get(keys.RGB), whole.get(keys.RGB)[rows])
    assert torch.equal(part.get(("nested", "x")), whole.get(("nested", "x"))[rows])
    assert keys.SCENE not in part.keys()
    with pytest.raises(ValueError, match="bool mask over the 12 records"):
        load_records(root, rows=torch.ones(5, dtype=torch.bool))


def test_frames_of_two_stores_by_rows(tmp_path):
    a = _store(tmp_path / "a", [[0, 1, 2, 3, 4, 5], [6, 7, 8, 9, 10, 11]])
    b = _store(tmp_path / "b", [[11, 10, 9, 8, 7, 6], [5, 4, 3, 2, 1, 0]], scene_base=100)
    whole = load_frames([a, b])
    assert whole.shape[0] == 24 and whole.get(keys.SCENE)[12:].min() >= 1_000_000   # scene ids distinct per store
    rows = torch.arange(24) % 3 == 1
    part = load_frames([a, b], [keys.RGB, keys.SCENE], rows=rows)
    assert torch.equal(part.get(keys.RGB), whole.get(keys.RGB)[rows])
    assert torch.equal(part.get(keys.SCENE), whole.get(keys.SCENE)[rows])
    with pytest.raises(ValueError, match="rows has 23 entries, the stores hold 24"):
        load_frames([a, b], rows=rows[:23])


def test_two_stores_of_the_same_piles_share_scene_ids_so_a_split_by_scene_holds_a_pile_out_of_both(tmp_path):
    from mqa_rl.training.vqa_data import scene_split

    a = _store(tmp_path / "a", [list(range(12))], dataset="piles")
    b = _store(tmp_path / "b", [list(range(12))], dataset="piles")            # the same piles, other pushes
    c = _store(tmp_path / "c", [list(range(12))], dataset="other piles")
    frames = load_frames([a, b, c], [keys.SCENE])
    scenes = frames.get(keys.SCENE)
    assert torch.equal(scenes[:12], scenes[12:24]) and scenes[24:].min() >= 1_000_000
    frames.set(keys.LEVEL, torch.zeros(36, dtype=torch.int64))
    held = scene_split(frames, 0.5, seed=0)
    assert torch.equal(held[:12], held[12:24]) and held[:24].any()           # held out of both stores alike
    trained = set(scenes[~held].tolist())
    assert not trained & set(scenes[held].tolist())


def test_a_truncated_chunk_is_refused_naming_the_file_and_sizes_never_read_as_zeros(tmp_path):
    from mqa_rl.files import TruncatedFile

    root = _store(tmp_path / "a", [[0, 1, 2, 3], [4, 5, 6, 7, 8, 9, 10, 11]])
    rgb = root / "chunk-00000" / f"{keys.RGB}.memmap"
    rgb.write_bytes(rgb.read_bytes()[:100])                    # an interrupted copy
    with pytest.raises(TruncatedFile, match=r"rgb.memmap holds 100 bytes where .* expects 768"):
        load_records(root)
    with pytest.raises(TruncatedFile):                         # a second collection does not call the store complete
        with EpisodeStore(root, {"slots": 12, "plan": {"size": 8}}) as store:
            store.done_slots()


def test_a_broken_meta_json_or_an_empty_chunk_is_named(tmp_path):
    from mqa_rl.collectors.store import StoreError, read_meta

    root = _store(tmp_path / "a", [[0, 1, 2, 3]])
    (root / "chunk-00000" / "meta.json").write_text("{not json")
    with pytest.raises(ValueError, match=r"chunk-00000/meta.json is not readable JSON"):
        load_records(root, require_complete=False)
    (root / "chunk-00000" / "meta.json").unlink()
    with pytest.raises(ValueError, match=r"chunk-00000 has no meta.json"):
        load_records(root, require_complete=False)
    (root / "meta.json").write_text("{")
    with pytest.raises(StoreError, match=r"meta.json is not readable JSON"):
        read_meta(root)


def test_overwrite_never_removes_the_chunks_of_a_store_another_writer_holds(tmp_path):
    from mqa_rl.collectors.store import StoreError

    root = tmp_path / "a"
    with EpisodeStore(root, {"slots": 12, "plan": {"size": 8}}) as first:
        first.append(TensorDict({keys.SLOT: torch.arange(4)}, batch_size=[4]))
        with pytest.raises(StoreError, match="being written by another process"):
            EpisodeStore(root, {"slots": 12, "plan": {"size": 9}}, overwrite=True)
        assert first.done_slots() == {0, 1, 2, 3}             # untouched
    with EpisodeStore(root, {"slots": 12, "plan": {"size": 9}}, overwrite=True) as second:   # free now: replaced
        assert second.done_slots() == set()
