"""Table III as measured: each MQA system (its frozen policy's test rollouts answered by the VQA trained
on its training rollouts), COUNTING accuracy per level beside the paper's, with 95 % intervals.

    python recipes/evaluate.py                                  # questions=counting vqa=counting
    python recipes/evaluate.py vqa=eqa                          # the VQAs trained with the paper's (EQA's) model
    python recipes/evaluate.py questions=all_types              # all four question types, per type and level
    python recipes/evaluate.py 'report=[random,no_manipulation]'

Per system also: accuracy per question type and level, the difference to random paired by question,
mean pushes, the targets' χ at the end and its change, and what a perfect counter would read from the
first image, the last, and either of them (is the policy or the VQA the limit?) and a calibrated counter (that count on the last image
mapped to the answer it most often meant in the system's training rollouts: what a count-reading VQA can reach);
as references, the training split's
majority answer per type and level (what a VQA blind to the images reaches). A system whose policy
checkpoint, VQA or rollouts do not exist is reported as missing, with the command that makes it;
missing test rollouts of an available policy are collected first (``collect_missing``).

Writes to ``out_dir``: ``table3.md`` / ``.csv`` / ``.png``, ``per_type.md``, ``policy.md``,
``fig7_rewards.png`` (from the DQN runs' logs), ``results.json``.
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import json
import time
import warnings
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.rollouts import collect_split, plan_questions, questions_sha256
from mqa_rl.collectors.store import StoreError, load_records, read_meta
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import LEVELS
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.evaluation import answering as ans
from mqa_rl.evaluation import answering_report as report
from mqa_rl.files import write_atomic
from mqa_rl.modules.answering.vqa import CHECKPOINT_NAME, answer_size_for, load_vqa
from mqa_rl.modules.answering.vqa_ensemble import VQAEnsemble
from mqa_rl.modules.frozen_policies import resolve_checkpoint
from mqa_rl.modules.systems import system_spec, table3_systems
from mqa_rl.training.run_logger import RunLogger
from mqa_rl.training.vqa_data import (IMAGE_KEYS, RECORD_KEYS, encode_store, encoder_fingerprint, frame_keys,
                                     load_answering_records)

EVAL_KEYS = (*RECORD_KEYS, keys.EPISODE_TARGETS, (keys.FIRST, keys.FRAME_VISIBLE),
             (keys.LAST, keys.FRAME_VISIBLE))
# what the calibrated counter reads from the training rollouts
COUNT_KEYS = (keys.TYPE_LABEL, keys.LEVEL, keys.ANSWER_LABEL, keys.EPISODE_TARGETS, (keys.FIRST, keys.FRAME_VISIBLE),
              (keys.LAST, keys.FRAME_VISIBLE))


def vqa_dirs(cfg: DictConfig) -> list[str]:
    """``vqa_dir``: one folder of train_vqa.py runs, or a list of them (seeds) whose VQAs answer together."""
    dirs = cfg.vqa_dir if OmegaConf.is_list(cfg.vqa_dir) else [cfg.vqa_dir]
    if not dirs:
        raise ValueError("vqa_dir=[] names no VQA folder: give one folder, or a list of seeds' folders")
    return [str(d) for d in dirs]


def missing(reason: str, command: str) -> dict:
    return {"status": "missing", "reason": f"{reason}; run: `{command}`", "command": command}


def policy_command(name: str, run: str) -> str:
    """The command that trains system ``name``'s policy into ``run``: a DQfD variant continues a student
    (pipeline=reward_variants writes ROOT/<variant>/{dqn,stop}), anything else is a train_dqn.py run."""
    path = Path(run)
    variant = name.removeprefix("dqfd_")
    if name.startswith("dqfd_") and path.name == "dqn" and path.parent.name == variant:
        return (f"python recipes/pipeline.py pipeline=student root=runs/student seed=1 && python recipes/pipeline.py "
                f"pipeline=reward_variants student=runs/student root={path.parents[1]} 'variants=[{variant}]'")
    return f"python recipes/train_dqn.py reward=<variant> out_dir={run}"


def evaluate_system(cfg: DictConfig, ds: MQADataset, name: str, plan_sha: str) -> tuple[dict, TensorDict | None, torch.Tensor | None]:
    """(result, test records, right [N]) of one system; records and right are None when it is missing."""
    spec = system_spec(cfg.systems, name)
    q, v = cfg.questions.name, cfg.vqa.name
    try:
        spec = resolve_checkpoint(spec)
    except FileNotFoundError:
        return missing(f"no trained policy in {spec['run']}", policy_command(name, spec["run"])), None, None
    store = Path(cfg.rollouts_dir) / name / "test"
    vqa_paths = [Path(d) / name / CHECKPOINT_NAME for d in vqa_dirs(cfg)]
    train_cmd = (f"python recipes/collect.py what=rollouts system={name} questions={q} vqa={v} && "
                 f"python recipes/train_vqa.py system={name} questions={q} vqa={v}")
    absent = [p for p in vqa_paths if not p.exists()]
    if absent:
        return missing(f"no VQA at {absent[0]}", train_cmd), None, None
    model = load_vqa(vqa_paths[0]) if len(vqa_paths) == 1 else VQAEnsemble.load(vqa_paths)
    collection = OmegaConf.to_container(cfg.collection, resolve=True)
    answer_size = answer_size_for([model], int(collection["env"]["image_size"]))
    if answer_size is not None:                       # the VQA reads the answer camera's frames
        collection["env"]["answer_size"] = answer_size
    t0 = time.perf_counter()
    try:
        records = load_records(store, EVAL_KEYS)
    except (FileNotFoundError, StoreError) as error:
        if not cfg.collect_missing:
            return missing(f"no complete test rollouts ({error})", f"python recipes/collect.py what=rollouts system={name} "
                                                                   f"questions={q} vqa={v} 'splits=[test]'"), None, None
        collect_split(store, "test", dataset=ds, policy=spec, questions=OmegaConf.to_container(cfg.questions),
                      collection=collection, progress=cfg.progress, ray_address=cfg.ray.address)
        records = load_records(store, EVAL_KEYS)
    collect_seconds = time.perf_counter() - t0
    if read_meta(store)["plan"]["questions_sha256"] != plan_sha:
        return missing(f"the test rollouts in {store} cover other questions than questions={q} asks",
                       f"python recipes/collect.py what=rollouts system={name} questions={q} 'splits=[test]' overwrite=true"), None, None
    if read_meta(store)["policy"] != spec:
        warnings.warn(f"{store} was collected with policy {read_meta(store)['policy']}, the config now says {spec}",
                      stacklevel=2)
    model.check_dataset(ds)
    members = model.meta.get("members", [model.meta])
    for path, meta in zip(vqa_paths, members):
        trained_on = meta.get("rollouts_split") or Path(str(meta.get("rollouts", ""))).name
        if trained_on == "test":
            raise ValueError(f"{path} was trained on test-split rollouts ({meta.get('rollouts')}): Table III scores the "
                             f"test split, so it would be scored on what it learnt; train it on the training split's rollouts")
        if meta.get("system") not in (None, name):
            warnings.warn(f"{path} was trained on the rollouts of {meta['system']!r}, not {name!r}", stacklevel=2)
    try:   # the frames this VQA reads: the answer camera's where its perception reads finer than the env renders
        frame_keys(store, model.frame_size)
    except ValueError as error:
        return missing(str(error), f"python recipes/collect.py what=rollouts system={name} questions={q} 'splits=[test]' "
                                   f"collection.env.answer_size={model.frame_size} overwrite=true"), None, None
    t1 = time.perf_counter()
    right = predict_from_store(model, store, records, cfg.batch_size) == records.get(keys.ANSWER_LABEL)
    counting = records.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting")
    sub = records[counting]
    vqa_meta = [{k: meta.get(k) for k in ("step", "train_episodes", "val_episodes")} for meta in members]
    result = {"status": "ok", "episodes": records.shape[0], "rollouts": str(store), "policy_spec": spec,
              "vqa": str(vqa_paths[0]) if len(vqa_paths) == 1 else [str(p) for p in vqa_paths],
              "vqa_meta": vqa_meta[0] if len(vqa_meta) == 1 else vqa_meta,
              "accuracy": ans.accuracy_table(right, records),
              "counter_first": ans.accuracy_table(ans.counter_right(sub, ds.answers, keys.FIRST), sub),
              "counter_last": ans.accuracy_table(ans.counter_right(sub, ds.answers, keys.LAST), sub),
              "counter_either": ans.accuracy_table(ans.counter_right(sub, ds.answers, ans.EITHER), sub),
              **calibrated_counter(Path(cfg.calibration_rollouts_dir) / name / "train", sub),
              "policy": ans.policy_stats(records),
              "seconds": {"collect_or_load": round(collect_seconds, 1), "answer": round(time.perf_counter() - t1, 1)}}
    return result, records, right


def predict_from_store(model, store, records: TensorDict, batch_size: int = 64) -> torch.Tensor:
    """``predict`` for ``records`` (a rollout store's records in slot order, without their frames). A counting VQA,
    or seeds of one on a shared perception (``feature_reader``), answers from the perception's features cached
    under the store by ``encode_store``, as its training read them: a second evaluation, or another seed, skips
    the perception (~100 s for a store's 600 pairs of 448-px frames on 2 cores). Other VQAs read the frames."""
    reader = model.feature_reader
    if reader is None:
        frames = load_answering_records(store, size=model.frame_size).select(keys.SLOT, *IMAGE_KEYS)
        _check_slots(records, frames, store)
        return ans.predict(model, frames.update(records.select(keys.QUESTION)), batch_size)
    device = next(reader.parameters()).device
    reader.eval()
    feats = encode_store(store, lambda x: reader.encode_frames(x.to(device)).cpu(), batch_size=batch_size,
                         size=reader.frame_size, cache_key=encoder_fingerprint(reader.encoder))
    _check_slots(records, feats, store)
    reader.check_tokens(records.get(keys.QUESTION))
    out = []
    for start in range(0, records.shape[0], batch_size):
        question = records.get(keys.QUESTION)[start:start + batch_size]
        first, last = (feats.get(k)[start:start + batch_size, 0].float() for k in (keys.FIRST_FEATURES, keys.LAST_FEATURES))
        out.append(model.answer_probs_from_features(question, first, last).argmax(-1))
    return torch.cat(out) if out else torch.zeros(0, dtype=torch.int64)


def _check_slots(records: TensorDict, read: TensorDict, store) -> None:
    if not torch.equal(records.get(keys.SLOT), read.get(keys.SLOT)):
        raise ValueError(f"{store} changed while it was read (other episodes than its records): evaluate it again")


def calibrated_counter(train_store: Path, test: TensorDict) -> dict:
    """{"counter_calibrated": ..., "counter_calibrated_either": ...} accuracy tables of the perfect count on
    I_stop, and on either frame, mapped to answers as in the system's training rollouts
    (``ans.calibrated_counter_right``): the ceilings of a VQA that reads the count on I_stop, or on both
    frames; {} when those rollouts are gone."""
    try:
        train = load_records(train_store, COUNT_KEYS)
    except (FileNotFoundError, StoreError):
        return {}
    return {"counter_calibrated": ans.accuracy_table(ans.calibrated_counter_right(train, test, keys.LAST), test),
            "counter_calibrated_either": ans.accuracy_table(ans.calibrated_counter_right(train, test, ans.EITHER), test)}


def read_stored(path) -> dict | None:
    """The stored result of a larger evaluation to show beside this one (``stored_results``), or None."""
    if not path:
        return None
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"stored_results={path} does not exist: give a results file like "
                                f"checkpoints/vqa_counting/test_split_results.json, or stored_results=null")
    try:
        stored = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"stored_results={path} is not readable JSON ({error}): give a results file like "
                         f"checkpoints/vqa_counting/test_split_results.json, or stored_results=null") from error
    if not isinstance(stored, dict) or not isinstance(stored.get("systems"), dict) or "command" not in stored:
        raise ValueError(f"stored_results={path} has no 'systems' and 'command' entries: it is not a stored Table III "
                         f"(see checkpoints/vqa_counting/test_split_results.json)")
    return stored


def report_markdown(cfg: DictConfig, head: str, t3: str, paired: str, reading: list[str], stored: dict | None) -> str:
    """The page a reader opens first: Table III beside the paper's, every system against no manipulation and random
    paired by question, which system answers best, what this sample can separate, where the figure and videos are."""
    parts = ["# Table III, as measured", "", head, "", t3, "", "![Table III](table3.png)", "",
             "## Paired by question, 95 % intervals by scene (bold: beyond noise)", "", paired, "", *reading, ""]
    if stored:
        parts += [f"Stored, full test split: {stored.get('what', '')}; made by `{stored['command']}`.", ""]
    parts += ["Also here: `by_scene.md` (every difference with its scene count), `per_type.md`, `policy.md` (pushes, χ, "
              "perfect counters), `table3.csv`, `results.json`."]
    if cfg.get("videos_dir"):
        parts += [f"Videos of episodes with the Q-network's map: `{cfg.videos_dir}`."]
    return "\n".join(parts) + "\n"


def evaluate(cfg: DictConfig) -> dict:
    stored = read_stored(cfg.stored_results)       # before minutes of collecting
    ds = MQADataset(cfg.dataset)
    names = list(cfg.report) if cfg.report else table3_systems(cfg.systems)
    for name in names:                           # before minutes of collecting the others
        system_spec(cfg.systems, name)
    results: dict = {"questions": cfg.questions.name, "vqa": cfg.vqa.name, "systems": {}, "references": {}}
    plan = plan_questions(ds, "test", list(cfg.questions.types), None, cfg.questions.max_per_group["test"],
                          int(cfg.collection.seed))
    plan_sha = questions_sha256(plan)
    data = {}
    for name in names:
        res, records, right = evaluate_system(cfg, ds, name, plan_sha)
        results["systems"][name] = res
        if records is not None:
            data[name] = (records, right)
        status = "ok" if res["status"] == "ok" else res["reason"]
        print(f"{name}: {status}", flush=True)
    # paired differences to random, per level, on COUNTING
    if "random" in data:
        r_rec, r_right = data["random"]
        r_mask = r_rec.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting")
        for name, (records, right) in data.items():
            if name == "random":
                continue
            counting = records.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting")
            for key, paired in (("vs_random", ans.paired_difference), ("vs_random_by_scene", ans.paired_difference_by_scene)):
                results["systems"][name][key] = {
                    lv: paired(right, records, r_right[r_mask], r_rec[r_mask], mask_a=counting & (records.get(keys.LEVEL) == i))
                    for i, lv in enumerate(LEVELS)}
    # intervals that resample scenes: every system's accuracy, and its difference to no manipulation
    for name, (records, right) in data.items():
        results["systems"][name]["accuracy_by_scene"] = ans.accuracy_by_scene(right, records)
    if "no_manipulation" in data:
        n_rec, n_right = data["no_manipulation"]
        n_mask = n_rec.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting")
        n_counter = ans.counter_right(n_rec, ds.answers, keys.LAST)[n_mask]     # the counter on I_start
        for name, (records, right) in data.items():
            counting = records.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting")
            if name != "no_manipulation":
                results["systems"][name]["vs_no_manipulation_by_scene"] = {
                    lv: ans.paired_difference_by_scene(right, records, n_right[n_mask], n_rec[n_mask],
                                                       mask_a=counting & (records.get(keys.LEVEL) == i))
                    for i, lv in enumerate(LEVELS)}
                # what the policy's stop leaves a perfect counter, against not pushing
                results["systems"][name]["counter_stop_vs_no_manipulation_by_scene"] = {
                    lv: ans.paired_difference_by_scene(ans.counter_right(records, ds.answers, keys.LAST), records,
                                                       n_counter, n_rec[n_mask],
                                                       mask_a=counting & (records.get(keys.LEVEL) == i))
                    for i, lv in enumerate(LEVELS)}
    # paired differences to the answer prior (the training split's majority answer per type and level; a
    # held-out set of fresh piles has no training split: ``prior_dataset`` names the one that has)
    prior = ans.prior_answers(MQADataset(cfg.prior_dataset) if str(cfg.prior_dataset) != str(cfg.dataset) else ds, "train")
    if not prior:
        raise ValueError(f"{cfg.prior_dataset} has no training split to take the answer prior from: set prior_dataset= "
                         f"to the dataset the VQAs were trained on (e.g. data/mqa)")
    for name, (records, right) in data.items():
        counting = records.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting")
        for key, paired in (("vs_prior", ans.paired_difference), ("vs_prior_by_scene", ans.paired_difference_by_scene)):
            results["systems"][name][key] = {
                lv: paired(right, records, ans.prior_right(records, prior), records, mask_a=counting & (records.get(keys.LEVEL) == i))
                for i, lv in enumerate(LEVELS)}
    # the answer prior on the test plan's questions (needs no rollout)
    qs = [ds.questions[i] for i in plan]
    answer_index = {a: i for i, a in enumerate(ds.answers)}
    plan_td = TensorDict({
        keys.TYPE_LABEL: torch.tensor([QUESTION_TYPES.index(q.type) for q in qs]),
        keys.LEVEL: torch.tensor([LEVELS.index(ds.scene(q.scene_id).difficulty) for q in qs]),
        keys.ANSWER_LABEL: torch.tensor([answer_index[q.answer] for q in qs])}, batch_size=[len(qs)])
    results["references"]["answer prior (train majority per type and level)"] = ans.accuracy_table(
        ans.prior_right(plan_td, prior), plan_td)

    out = Path(cfg.out_dir)
    head = (f"COUNTING accuracy on the test split of {cfg.dataset} ({cfg.questions.name} questions, VQA {cfg.vqa.name}), ± Wilson 95 % "
            f"half-width; paper: Table III of Deng et al. (RSS 2021)")
    t3 = report.table3_markdown(results)
    paired = report.paired_markdown(results, stored)
    reading = [report.best_line(results, stored), report.sample_line(results)]
    write_atomic(out / "table3.md", f"{head}\n\n{t3}\n")
    write_atomic(out / "table3.csv", report.rows_csv(results))
    report.table3_figure(results, out / "table3.png")
    write_atomic(out / "report.md", report_markdown(cfg, head, t3, paired, reading, stored))
    per_type = report.per_type_markdown(results)
    write_atomic(out / "per_type.md", f"Accuracy per question type and level (± Wilson 95 %)\n\n{per_type}\n")
    policy = report.policy_markdown(results)
    write_atomic(out / "policy.md", "Policies on the test rollouts (± 95 %); perfect counter: targets with "
                                          f">= 20 visible px counted, COUNTING only\n\n{policy}\n")
    if cfg.fig7:
        runs = [Path(results["systems"][n]["policy_spec"]["run"]) for n in data
                if results["systems"][n]["policy_spec"]["kind"] == "dqn"]
        runs = [r for r in runs if (r / "csv" / "scalars" / "train" / "reward.csv").exists()]
        if runs:
            from mqa_rl.evaluation.reward_curves import plot_reward_curves

            plot_reward_curves(runs, out / "fig7_rewards.png")
    write_atomic(out / "by_scene.md", report.by_scene_markdown(results))
    write_atomic(out / "results.json", json.dumps(results, indent=1, default=float))
    with RunLogger(out, cfg.logger, exp_name="table3", files=False) as dashboards:    # beside the runs, under runs/
        for name in ("report", "per_type", "policy"):
            dashboards.log_text(f"table3/{name}", (out / f"{name}.md").read_text(), 0)
        dashboards.log_figure("table3/figure", out / "table3.png", 0)
    print(f"\n{head}\n\n{t3}\n\n{paired}\n")
    print("\n".join(reading))
    print(f"\n{per_type}\n\n{policy}\n\nwritten to {out}")
    return results


@hydra.main(config_path="conf", config_name="evaluate", version_base="1.3")
def main(cfg: DictConfig) -> None:
    evaluate(cfg)


if __name__ == "__main__":
    main()
