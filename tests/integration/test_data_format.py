"""Vocabulary, question templates, oracle answers and the on-disk format."""

import json
import shutil

import numpy as np
import pytest

from mqa_rl.data import DatasetError, MQADataset
from mqa_rl.data.questions import question_text, scene_questions, under_matrix
from mqa_rl.data.storage import SCHEMA_VERSION, write_dataset_atomically
from mqa_rl.data.vocab import Vocabulary, words

PHRASES = {"can": ("a can", "cans"), "apple": ("an apple", "apples"), "scissors": ("a pair of scissors", "scissors")}


def test_templates_read_naturally():
    assert question_text("counting", ("apple",), PHRASES) == "How many apples are there in the bin?"
    assert question_text("existence", ("apple",), PHRASES) == "Is there an apple in the bin?"
    assert question_text("spatial", ("can", "scissors"), PHRASES) == "Is there a can under the pair of scissors?"
    assert question_text("logic", ("scissors", "apple"), PHRASES) == "Is there a pair of scissors and an apple in the bin?"
    with pytest.raises(ValueError, match="allowed"):
        question_text("colour", ("can",), PHRASES)


def test_vocabulary_roundtrip_and_unknown_words():
    v = Vocabulary.build(["How many cans are there in the bin?"])
    assert v.itos[:2] == ("<pad>", "<unk>")
    toks = v.encode("How many cans are there in the bin?")
    assert v.decode(toks) == " ".join(words("How many cans are there in the bin?"))
    assert v.encode("How many zebras") [-1] == 1


def test_under_requires_overlap_and_height():
    sil = np.zeros((3, 10, 10), bool)
    sil[0, 2:6, 2:6] = True          # a
    sil[1, 4:8, 4:8] = True          # b overlaps a
    sil[2, 8:10, 0:2] = True         # c far away
    heights = np.array([0.01, 0.05, 0.09])
    u = under_matrix(sil, heights)
    assert u[0, 1] and not u[1, 0]   # a under b (lower, overlapping), not the reverse
    assert not u[0, 2] and not u[2, 0]


def test_scene_questions_answers_and_counts():
    classes = ("can", "apple", "scissors")
    objs = ["can", "can", "apple"]                    # no scissors
    under = np.zeros((3, 3), bool)
    under[2, 0] = True                                # the apple is under a can
    qs = {q[0]: q for q in scene_questions("s", objs, under, classes, PHRASES)}
    assert len(qs) == 3 + 3 + 6 + 6
    assert qs["s/counting/can"][3] == "2" and qs["s/counting/scissors"][3] == "0"
    assert qs["s/existence/apple"][3] == "yes" and qs["s/existence/scissors"][3] == "no"
    assert qs["s/spatial/apple/can"][3] == "yes" and qs["s/spatial/can/apple"][3] == "no"
    assert qs["s/logic/can/apple"][3] == "yes" and qs["s/logic/can/scissors"][3] == "no"


def test_atomic_write_leaves_nothing_when_interrupted(tmp_path):
    files = {"a.txt": b"x", "b/c.txt": None}          # writing None fails half-way
    with pytest.raises(TypeError):
        write_dataset_atomically(tmp_path / "ds", files, {})
    assert list(tmp_path.iterdir()) == []


def _copy(src, tmp_path):
    dst = tmp_path / "copy"
    shutil.copytree(src, dst)
    return dst


def test_corrupt_partial_and_newer_datasets_are_refused(small_dataset_dir, tmp_path):
    d = _copy(small_dataset_dir, tmp_path)
    (d / "questions.jsonl").write_bytes((d / "questions.jsonl").read_bytes()[:-50])
    with pytest.raises(DatasetError, match="checksum"):
        MQADataset(d)
    shutil.rmtree(d)
    d = _copy(small_dataset_dir, tmp_path)
    (d / "scenes.json").unlink()
    with pytest.raises(DatasetError, match="missing"):
        MQADataset(d)
    shutil.rmtree(d)
    d = _copy(small_dataset_dir, tmp_path)
    m = json.loads((d / "manifest.json").read_text())
    m["schema_version"] = SCHEMA_VERSION + 1
    (d / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DatasetError, match="newer"):
        MQADataset(d)
    (d / "manifest.json").write_text("{not json")
    with pytest.raises(DatasetError, match="corrupt"):
        MQADataset(d)
    (d / "manifest.json").unlink()
    with pytest.raises(DatasetError, match="not a complete"):
        MQADataset(d)
    with pytest.raises(DatasetError, match="does not exist"):
        MQADataset(tmp_path / "nowhere")


def test_existing_folder_is_not_overwritten_by_accident(small_dataset_dir):
    from mqa_rl.data import generate_dataset

    with pytest.raises(FileExistsError, match="overwrite"):
        generate_dataset(small_dataset_dir, num_scenes={"easy": 1})
    MQADataset(small_dataset_dir)        # still valid
