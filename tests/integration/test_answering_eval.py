"""recipes/evaluate.py on a tiny pipeline: Table III beside the paper's (markdown, CSV, PNG), the
per-type and policy tables, missing systems named with their command, test rollouts collected when
missing, a mismatched VQA refused; and the statistics it is built from."""

import csv
import json
import os
import subprocess
import sys

import pytest
import torch
from conftest import REPO as ROOT, compose_recipe_config, load_recipe
from tensordict import TensorDict
from torch_threads import one_torch_thread  # noqa: F401  (autouse)

from mqa_rl import keys
from mqa_rl.evaluation import answering as ans
from mqa_rl.modules.answering.vqa import VQAModel, save_vqa


def test_statistics():
    p, lo, hi = ans.wilson(5, 10)
    assert p == 0.5 and abs(lo - 0.2366) < 1e-3 and abs(hi - 0.7634) < 1e-3
    assert ans.wilson(0, 4)[1] == 0.0 and all(x != x for x in ans.wilson(0, 0))
    rec = lambda q: TensorDict({keys.QUESTION_ID: torch.tensor(q)}, batch_size=[len(q)])   # noqa: E731
    # A right on questions 1, 2 (2 rollouts of question 2: half right), B right on question 1 only
    mean, half, n = ans.paired_difference(torch.tensor([True, True, False]), rec([1, 2, 2]),
                                          torch.tensor([True, False, False]), rec([1, 2, 3]))
    assert n == 2 and mean == pytest.approx(0.25)
    counting = TensorDict({keys.EPISODE_TARGETS: torch.tensor([[True, True, False], [True, False, False]]),
                           (keys.LAST, keys.FRAME_VISIBLE): torch.tensor([[30.0, 5.0, 99.0], [0.0, 50.0, 50.0]]),
                           keys.ANSWER_LABEL: torch.tensor([1, 1]), keys.TYPE_LABEL: torch.tensor([0, 0])}, batch_size=[2])
    answers = ("0", "1", "2", "3", "yes", "no")
    assert ans.counter_right(counting, answers).tolist() == [True, False]   # 1 target seen of 1 / none of 1


def test_either_frame_counter_counts_each_target_seen_in_one_of_the_two_images_once():
    """Three targets: one countable only in I_start, one only in I_stop, one in both; a fourth object is no target.
    Either frame counts 3 (each object once), where each frame alone counts 2 and their larger count is 2."""
    rec = TensorDict({keys.EPISODE_TARGETS: torch.tensor([[True, True, True, False]]),
                      (keys.FIRST, keys.FRAME_VISIBLE): torch.tensor([[40.0, 0.0, 25.0, 90.0]]),
                      (keys.LAST, keys.FRAME_VISIBLE): torch.tensor([[19.0, 60.0, 30.0, 90.0]]),
                      keys.ANSWER_LABEL: torch.tensor([3]), keys.TYPE_LABEL: torch.tensor([0])}, batch_size=[1])
    assert ans.countable_targets(rec, keys.FIRST).item() == ans.countable_targets(rec, keys.LAST).item() == 2
    assert ans.countable_targets(rec, ans.EITHER).item() == 3
    answers = ("0", "1", "2", "3", "yes", "no")
    assert ans.counter_right(rec, answers, ans.EITHER).tolist() == [True]
    assert ans.counter_right(rec, answers, keys.LAST).tolist() == [False]


def test_calibrated_counter_maps_each_visible_count_to_its_most_frequent_answer_per_level():
    def records(level, seen, answer, qtype=None):
        """One target per episode, visible (30 px) or hidden (0 px)."""
        n = len(level)
        return TensorDict({keys.LEVEL: torch.tensor(level), keys.ANSWER_LABEL: torch.tensor(answer),
                           keys.TYPE_LABEL: torch.tensor(qtype or [0] * n),
                           keys.EPISODE_TARGETS: torch.ones(n, 1, dtype=torch.bool),
                           (keys.LAST, keys.FRAME_VISIBLE): torch.tensor([[30.0 * s] for s in seen])}, batch_size=[n])
    # hard (level 2): one visible target was a 3 twice, a 1 once; easy (level 0): one visible is a 1.
    # The yes/no question (type 1) with answer 4 must not count.
    train = records([2, 2, 2, 0, 0, 2], [1, 1, 1, 1, 0, 1], [3, 3, 1, 1, 0, 4], [0, 0, 0, 0, 0, 1])
    test = records([2, 2, 0, 0, 0], [1, 0, 1, 0, 1], [3, 3, 1, 0, 1], [0, 0, 0, 0, 1])
    right = ans.calibrated_counter_right(train, test)
    # a count never seen at that level falls back to the level's majority (hard: 3); non-counting is False
    assert right.tolist() == [True, True, True, True, False]
    # the plain counter says 1 where the calibrated one says 3
    assert ans.counter_right(test, ("0", "1", "2", "3", "yes", "no")).tolist() == [False, False, True, True, False]


@pytest.fixture(scope="module")
def trained(answering_root):
    root, overrides = answering_root
    train_vqa = load_recipe("train_vqa")
    for system in ("random", "no_manipulation"):
        train_vqa.train(compose_recipe_config("train_vqa", [
            *overrides, f"system={system}", "encoder.weights=null", "encoder.freeze=false", "train.steps=3", "train.batch_size=4",
            "train.eval_interval=3", "logger=csv", "logger.progress=false", "vqa=eqa"]))
    return root, [*overrides, "vqa=eqa"]              # the paper's VQA: a tiny one trains in seconds


def test_evaluate_writes_table3_and_names_what_is_missing(small_dataset, trained, tmp_path):
    root, overrides = trained
    test_store = root / "rollouts" / "counting" / "no_manipulation" / "test"
    for chunk in test_store.glob("chunk-*"):        # lost test rollouts are collected again
        os.rename(chunk, tmp_path / chunk.name)
    evaluate = load_recipe("evaluate")
    results = evaluate.evaluate(compose_recipe_config("evaluate", [
        *overrides, "progress=false", f"systems.dqn_local.run={tmp_path / 'no_run'}",
        f"systems.dqfd_local.run={tmp_path / 'variants' / 'local' / 'dqn'}",
        "report=[random,no_manipulation,dqn_local,dqn_global,dqfd_local]"]))
    assert list(test_store.glob("chunk-*"))
    out = root / "report" / "counting-eqa"
    table = (out / "table3.md").read_text()
    assert "| random |" in table and "0.277 / 0.308 / 0.274" in table                 # the paper's beside ours
    assert "| dqn_local (DQN(R_l)) | missing" in table and "train_dqn.py" in table
    # a DQfD variant is made by continuing a student, and its hint says so
    assert (f"python recipes/pipeline.py pipeline=reward_variants student=runs/student root={tmp_path / 'variants'} "
            f"'variants=[local]'") in table
    assert "answer prior" in table
    sys_res = results["systems"]
    assert sys_res["random"]["status"] == "ok" and sys_res["dqn_global"]["status"] == "missing"
    assert set(sys_res["random"]["accuracy"]["counting"]) == {"easy", "hard", "all"}    # the test split's levels
    n = sum(c["n"] for lv, c in sys_res["random"]["accuracy"]["counting"].items() if lv != "all")
    assert n == sys_res["random"]["episodes"] == 4
    assert "vs_random" in sys_res["no_manipulation"]
    prior = results["references"]["answer prior (train majority per type and level)"]["counting"]
    for lv in ("easy", "hard"):            # one test rollout per question: the paired mean is the difference of accuracies
        mean, _, n = sys_res["random"]["vs_prior"][lv]
        assert n == prior[lv]["n"] and mean == pytest.approx(
            sys_res["random"]["accuracy"]["counting"][lv]["accuracy"] - prior[lv]["accuracy"])
    assert "− answer prior (paired)" in table
    assert sys_res["no_manipulation"]["policy"]["all"]["pushes"][0] == 0.0
    assert sys_res["no_manipulation"]["policy"]["all"]["countable_gain"][0] == 0.0      # I_stop is I_start
    assert sys_res["random"]["policy"]["all"]["countable_gain"][2] == 4
    with open(out / "table3.csv") as f:
        rows = list(csv.DictReader(f))
    assert {r["system"] for r in rows} >= {"random", "no_manipulation", "dqn_local"}
    assert any(r["status"] == "missing" and r["paper"] == "0.4458" for r in rows)
    assert (out / "table3.png").stat().st_size > 0 and "counting" in (out / "per_type.md").read_text()
    assert "perfect counter" in (out / "policy.md").read_text() and "calibrated on I_stop" in (out / "policy.md").read_text()
    assert set(sys_res["random"]["counter_calibrated"]["counting"]) == {"easy", "hard", "all"}
    either, last = sys_res["random"]["counter_calibrated_either"]["counting"], sys_res["random"]["counter_calibrated"]["counting"]
    assert set(either) == set(last) and "calibrated on either" in (out / "policy.md").read_text()
    assert "on either" in (out / "policy.md").read_text() and "counter_either" in rows[0]
    assert "made countable − buried" in (out / "policy.md").read_text()
    # intervals that resample scenes: an accuracy inside its own interval, and the paired gain over no manipulation
    for lv, (mean, low, high, scenes) in sys_res["random"]["accuracy_by_scene"].items():
        assert low <= mean <= high and scenes >= 1
        assert mean == pytest.approx(sys_res["random"]["accuracy"]["counting"][lv]["accuracy"])
    diff = sys_res["random"]["vs_no_manipulation_by_scene"]["easy"]
    assert diff[1] <= diff[0] <= diff[2] and "no manipulation" in (out / "by_scene.md").read_text()
    for lv in ("easy", "hard"):        # the counter on I_stop against I_start, paired: the difference of the two rates
        counter = sys_res["random"]["counter_stop_vs_no_manipulation_by_scene"][lv]
        rates = [sys_res[s]["counter_last"]["counting"][lv]["accuracy"] for s in ("random", "no_manipulation")]
        assert counter[0] == pytest.approx(rates[0] - rates[1]) and counter[1] <= counter[0] <= counter[2]
    assert "perfect counter on I_stop − no manipulation" in (out / "by_scene.md").read_text()
    for lv in ("easy", "hard"):        # − random and − the prior by scene: the paired means, with intervals around them
        by_scene, plain = sys_res["no_manipulation"]["vs_random_by_scene"][lv], sys_res["no_manipulation"]["vs_random"][lv]
        assert by_scene[0] == pytest.approx(plain[0]) and by_scene[1] <= by_scene[0] <= by_scene[2]
        by_scene, plain = sys_res["random"]["vs_prior_by_scene"][lv], sys_res["random"]["vs_prior"][lv]
        assert by_scene[0] == pytest.approx(plain[0]) and by_scene[1] <= by_scene[0] <= by_scene[2]
    assert "− random [95 %]" in (out / "by_scene.md").read_text() and "− prior [95 %]" in (out / "by_scene.md").read_text()
    assert json.loads((out / "results.json").read_text())["systems"]["random"]["episodes"] == 4


def test_evaluate_answers_with_the_mean_of_several_vqa_seeds(small_dataset, trained):
    """vqa_dir=[a, b]: every record answered by the argmax of the two VQAs' mean probabilities; a VQA of another
    vocabulary cannot join the ensemble."""
    from mqa_rl.modules.answering.vqa import load_vqa
    from mqa_rl.modules.answering.vqa_ensemble import VQAEnsemble
    from mqa_rl.training.vqa_data import load_answering_records

    root, overrides = trained
    load_recipe("train_vqa").train(compose_recipe_config("train_vqa", [
        *overrides, "system=random", "encoder.weights=null", "encoder.freeze=false", "train.steps=3", "train.batch_size=4",
        "train.eval_interval=3", "logger=csv", "logger.progress=false", "seed=1", f"out_dir={root / 'vqa_s1' / 'random'}"]))
    dirs = [root / "vqa" / "counting-eqa", root / "vqa_s1"]
    results = load_recipe("evaluate").evaluate(compose_recipe_config("evaluate", [
        *overrides, "progress=false", "report=[random]", f"vqa_dir=[{dirs[0]},{dirs[1]}]", f"out_dir={root / 'report_ens'}"]))
    res = results["systems"]["random"]
    assert res["vqa"] == [str(d / "random" / "vqa.pt") for d in dirs] and len(res["vqa_meta"]) == 2
    records = load_answering_records(root / "rollouts" / "counting" / "random" / "test")
    members = [load_vqa(d / "random") for d in dirs]
    first, last = (records.get(k).permute(0, 2, 3, 1) for k in (keys.FIRST_RGB, keys.LAST_RGB))
    probs = [m.answer_probs(records.get(keys.QUESTION), first, last) for m in members]
    ensemble = VQAEnsemble(members).answer_probs(records.get(keys.QUESTION), first, last)
    assert torch.allclose(ensemble, (probs[0] + probs[1]) / 2) and not torch.allclose(probs[0], probs[1])
    right = (ensemble.argmax(-1) == records.get(keys.ANSWER_LABEL)).float()
    assert res["accuracy"]["counting"]["all"]["accuracy"] == pytest.approx(float(right.mean()))
    with pytest.raises(ValueError, match="different question or answer vocabularies"):
        VQAEnsemble([members[0], VQAModel(["<pad>", "<unk>", "how", "many"], small_dataset.answers)])


def test_evaluate_refuses_a_vqa_of_another_vocabulary(small_dataset, trained):
    root, overrides = trained
    other = VQAModel(["<pad>", "<unk>", "how", "many"], small_dataset.answers)
    save_vqa(other, root / "vqa" / "counting-eqa" / "privileged" / "vqa.pt")
    evaluate = load_recipe("evaluate")
    with pytest.raises(ValueError, match="another question or answer vocabulary"):
        evaluate.evaluate(compose_recipe_config("evaluate", [*overrides, "progress=false", "report=[privileged]"]))


def test_evaluate_refuses_a_vqa_trained_on_test_rollouts(small_dataset, trained, tmp_path):
    _, overrides = trained
    leaky = VQAModel(small_dataset.vocab.itos, small_dataset.answers)
    save_vqa(leaky, tmp_path / "vqa" / "privileged" / "vqa.pt", {"system": "privileged", "rollouts_split": "test"})
    evaluate = load_recipe("evaluate")
    with pytest.raises(ValueError, match="trained on test-split rollouts"):
        evaluate.evaluate(compose_recipe_config("evaluate", [*overrides, "progress=false", "report=[privileged]",
                                                             f"vqa_dir={tmp_path / 'vqa'}"]))
    with pytest.raises(ValueError, match="unknown system.*'privilegd'"):       # named before any collecting
        evaluate.evaluate(compose_recipe_config("evaluate", [*overrides, "progress=false", "report=[random,privilegd]",
                                                             f"vqa_dir={tmp_path / 'vqa'}"]))


def test_evaluate_from_the_command_line(trained, tmp_path):
    root, overrides = trained
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, str(ROOT / "recipes" / "evaluate.py"), *overrides, "progress=false",
                          "collect_missing=false", "report=[random,dqn_global]", f"out_dir={tmp_path / 'report'}"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=600, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "| random |" in out.stdout and (tmp_path / "report" / "table3.md").exists()
    page = (tmp_path / "report" / "report.md").read_text()
    assert "| dqn_global (DQN(R_g)) | missing" in page                             # named with the paper's name
    assert "table3.png" in page and "goal" not in page.lower() and "issue" not in page.lower()


def test_the_report_pairs_every_system_with_the_baselines_says_which_answers_best_and_what_the_sample_separates():
    from mqa_rl.evaluation.answering_report import best_line, paired_markdown, sample_line

    levels = ("easy", "medium", "hard")

    def system(acc, vs_none=None, vs_random=None, n=30, scenes=9):
        res = {"status": "ok", "accuracy": {"counting": {lv: {"accuracy": acc, "n": n} for lv in levels}},
               "accuracy_by_scene": {lv: (acc, acc - 0.1, acc + 0.1, scenes) for lv in levels}}
        if vs_none is not None:
            res["vs_no_manipulation_by_scene"] = {lv: vs_none for lv in levels}
        if vs_random is not None:
            res["vs_random_by_scene"] = {lv: vs_random for lv in levels}
        return res

    results = {"systems": {"no_manipulation": system(0.70, vs_random=(0.02, -0.08, 0.12, 9)),
                           "random": system(0.68, vs_none=(-0.02, -0.12, 0.08, 9)),
                           "privileged": system(0.80, vs_none=(0.10, 0.02, 0.18, 9), vs_random=(0.12, 0.04, 0.20, 9)),
                           "dqn_global": {"status": "missing", "reason": "no checkpoint"}}}
    stored = {"command": "python recipes/evaluate.py ...", "systems": {
        "privileged": {"accuracy": {"easy": 0.95, "medium": 0.78, "hard": 0.69},
                       "vs_no_manipulation": {"easy": [0.044, 0.017, 0.078], "medium": [0.089, 0.022, 0.144],
                                              "hard": [0.083, 0.017, 0.150]}},
        "no_manipulation": {"accuracy": {"easy": 0.90, "medium": 0.69, "hard": 0.60}}}}
    table = paired_markdown(results, stored)
    rows = [line for line in table.splitlines() if line.startswith("| privileged")]
    assert len(rows) == 2                                   # − no manipulation, − random; baselines not paired with themselves
    assert "**+0.100 [+0.020, +0.180]**" in rows[0]        # beyond noise: bold
    assert "**+0.044 [+0.017, +0.078]**" in rows[0] and rows[1].endswith("| — |")   # stored beside; none against random
    assert "dqn_global" not in table
    assert "| random − " not in table and "no manipulation −" not in table
    assert "+0.020 [-0.080" not in table
    best = best_line(results, stored)
    assert best.startswith("Answers best on this sample (mean COUNTING accuracy over the levels): privileged 0.800")
    assert "Stored, full test split: privileged 0.807" in best
    line = sample_line(results)
    assert "easy 30 questions on 9 scenes" in line and "±0.09 / ±0.09 / ±0.09" in line
    assert "No paired difference" in sample_line({"systems": {"privileged": system(0.8)}})


def test_evaluate_collects_the_answer_cameras_frames_a_finer_vqa_reads(small_dataset, answering_root, tmp_path, monkeypatch):
    """A VQA on a perception that reads 448 px: evaluate.py collects its missing test rollouts with the answer camera
    and answers from its frames; a store of 224-px frames only is reported missing with the command that fixes it.
    The perception's features are kept beside the test store: answered from them as from the frames, and a second
    evaluation runs no perception."""
    from mqa_rl.modules.answering.perception import CountingPerception
    root, overrides = answering_root
    perception = CountingPerception(1 + len(small_dataset.classes), widths=(8, 8, 16, 16), image_size=448)
    model = VQAModel(small_dataset.vocab.itos, small_dataset.answers, pool="counts", cell_heads=2,
                     perception=perception.config())
    save_vqa(model, tmp_path / "vqa" / "no_manipulation" / "vqa.pt", {"system": "no_manipulation", "rollouts_split": "train"})
    evaluate = load_recipe("evaluate")
    base = [*overrides, "progress=false", "fig7=false", "report=[no_manipulation]", f"vqa_dir={tmp_path / 'vqa'}"]
    results = evaluate.evaluate(compose_recipe_config("evaluate", [*base, "collect_missing=false",
                                                                   f"out_dir={tmp_path / 'r224'}"]))
    gone = results["systems"]["no_manipulation"]
    assert gone["status"] == "missing" and "collection.env.answer_size=448" in gone["command"]
    results = evaluate.evaluate(compose_recipe_config("evaluate", [*base, f"rollouts_dir={tmp_path / 'rollouts'}",
                                                                   f"out_dir={tmp_path / 'r448'}"]))
    assert results["systems"]["no_manipulation"]["status"] == "ok"
    store = tmp_path / "rollouts" / "no_manipulation" / "test"
    meta = json.loads((store / "meta.json").read_text())
    assert meta["env"]["answer_size"] == 448
    from mqa_rl.modules.answering.vqa import load_vqa
    from mqa_rl.training.vqa_data import encode_store, encoder_fingerprint, load_answering_records
    assert len(list((store / "features").iterdir())) == 1
    loaded = load_vqa(tmp_path / "vqa" / "no_manipulation")
    frames = load_answering_records(store, size=448)
    first, last = (frames.get(k).permute(0, 2, 3, 1) for k in (keys.FIRST_RGB, keys.LAST_RGB))
    cached = encode_store(store, None, size=448, cache_key=encoder_fingerprint(loaded.encoder))   # None: read, not computed
    from_features = loaded.answer_probs_from_features(frames.get(keys.QUESTION), *(
        cached.get(k)[:, 0].float() for k in (keys.FIRST_FEATURES, keys.LAST_FEATURES)))
    assert torch.allclose(from_features, loaded.answer_probs(frames.get(keys.QUESTION), first, last), atol=1e-3)

    def no_perception(*args, **kwargs):
        raise AssertionError("the perception ran although its features are cached")
    monkeypatch.setattr(CountingPerception, "count_features", no_perception)
    again = evaluate.evaluate(compose_recipe_config("evaluate", [*base, f"rollouts_dir={tmp_path / 'rollouts'}",
                                                                 f"out_dir={tmp_path / 'again'}"]))
    assert again["systems"]["no_manipulation"]["accuracy"] == results["systems"]["no_manipulation"]["accuracy"]
