"""Learning to answer: the VQA loss falls on a small fixed batch, the encoder pretrains on a few
frames, and the train_vqa / pretrain recipes write loadable models, log, and resume."""

import csv
import shutil

import pytest
import torch
from conftest import compose_recipe_config, load_recipe
from tensordict import TensorDict
from torch_threads import one_torch_thread  # noqa: F401  (autouse)

from mqa_rl import keys
from mqa_rl.data.vocab import Vocabulary
from mqa_rl.losses.encoder_pretraining import EncoderPretrainLoss
from mqa_rl.losses.vqa import VQALoss
from mqa_rl.modules.answering.vqa import VQAModel, image_digest, load_vqa, vqa_module
from mqa_rl.modules.answering.vqa_encoder import FrameEncoder, PretrainHeads, load_encoder, save_encoder
from mqa_rl.training.frame_pack import load_frame_pack
from mqa_rl.training.vqa_build import build_model
from mqa_rl.training.vqa_data import Batches, encode_store, encoder_fingerprint, load_answering_records, pretraining_frames
from mqa_rl.envs.dihedral import dihedral
from mqa_rl.verified_checkpoint import CheckpointCorrupt

TEXTS = ["How many cans are there in the bin?", "How many apples are there in the bin?"]


def _squares(counts: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """Black images with ``count`` white 30 px squares each: a toy counting batch."""
    images = torch.zeros(len(counts), 3, 224, 224, dtype=torch.uint8)
    for i, k in enumerate(counts.tolist()):
        for _ in range(k):
            y, x = torch.randint(0, 190, (2,), generator=gen).tolist()
            images[i, :, y:y + 30, x:x + 30] = 255
    return images


def test_vqa_loss_decreases_on_a_fixed_batch():       # "classes" needs a pretrained class head (see below)
    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(0)
    model = VQAModel(Vocabulary.build(TEXTS).itos, ("0", "1", "2", "3", "yes", "no"), pool="eqa", dropout=0.0)
    loss = VQALoss(vqa_module(model))
    counts = torch.tensor([0, 1, 2, 3, 3, 2, 1, 0])
    batch = TensorDict({keys.QUESTION: model.tokenize(TEXTS * 4), keys.FIRST_RGB: _squares(counts, gen),
                        keys.LAST_RGB: _squares(counts, gen), keys.ANSWER_LABEL: counts}, batch_size=[8])
    optim = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=3e-3)
    with torch.no_grad():
        first = loss(batch)
    assert set(first.keys()) == {"loss_vqa", "accuracy"} and 0 <= float(first["accuracy"]) <= 1
    for _ in range(60):
        out = loss(batch)
        optim.zero_grad()
        out["loss_vqa"].backward()
        optim.step()
    with torch.no_grad():
        last = loss(batch)
    assert float(last["loss_vqa"]) < 0.5 * float(first["loss_vqa"])
    assert float(last["accuracy"]) > float(first["accuracy"])
    loss.set_keys(answer="other")                                       # keys are declared once, renamable
    assert "other" in loss.in_keys and keys.ANSWER_LABEL not in loss.in_keys


def test_dihedral_transforms_are_the_8_symmetries_of_the_square():
    x = torch.arange(9).view(1, 3, 3)
    images = {tuple(dihedral(x, k).flatten().tolist()) for k in range(8)}
    assert len(images) == 8 and torch.equal(dihedral(x, 0), x)


def test_encoder_pretrains_on_a_few_frames(small_dataset, answering_root, tmp_path):
    root, _ = answering_root
    store = root / "rollouts" / "counting" / "random" / "train"
    frames = pretraining_frames([store], small_dataset, max_frames=4, seed=0)
    assert frames.shape == (4,) and frames[keys.CLASS_MAP].dtype == torch.uint8
    for f in frames:                                         # classes follow from the objects' slots
        objects = small_dataset.scenes[int(f[keys.SCENE])].objects
        j = int(f[keys.OBJECT_MAP].max())
        name = small_dataset.classes[int(f[keys.CLASS_MAP][f[keys.OBJECT_MAP] == j][0]) - 1]
        assert name == objects[j - 1].class_name
    all_frames = pretraining_frames([store], small_dataset)
    scenes = all_frames[keys.SCENE].tolist()
    assert len(all_frames) <= len(set(scenes)) + 12           # each scene's first image once, then pushed ones
    torch.manual_seed(0)
    encoder = FrameEncoder(num_classes=1 + len(small_dataset.classes))
    loss = EncoderPretrainLoss(encoder, PretrainHeads(32, 1 + len(small_dataset.classes)),
                               camera_distance=small_dataset.camera.distance)
    optim = torch.optim.Adam(loss.parameters(), lr=2e-3)

    def total(out):
        return sum(v for k, v in out.items() if k.startswith("loss_"))

    with torch.no_grad():
        start = float(total(loss(frames)))
    for _ in range(15):
        out = loss(frames)
        optim.zero_grad()
        total(out).backward()
        optim.step()
    loss.eval()
    with torch.no_grad():
        end = loss(frames)
    assert float(total(end)) < 0.7 * start and 0 <= float(end["class_accuracy"]) <= 1
    assert 0 <= float(end["count_exact"]) <= 1
    path = save_encoder(encoder, tmp_path / "encoder.pt", {"frames": 4})
    again, meta = load_encoder(path)
    assert meta == {"frames": 4} and torch.equal(again.state_dict()["net.0.weight"], encoder.state_dict()["net.0.weight"])
    with pytest.raises(FileNotFoundError, match="pretrain.py part=vqa_encoder"):
        load_encoder(tmp_path / "none.pt")
    torch.save({"format": "mqa_rl.vqa"}, tmp_path / "vqa.pt")
    with pytest.raises(ValueError, match="not a VQA encoder file"):
        load_encoder(tmp_path / "vqa.pt")
    # frozen features of a store: one row per record, per dihedral transform
    model = VQAModel(small_dataset.vocab.itos, small_dataset.answers).eval()
    seen = []

    def counting(x):
        seen.append(x.shape[0])
        return model.encode_frames(x)
    records = encode_store(store, counting, transforms=2)
    assert records[keys.FIRST_FEATURES].shape == (records.shape[0], 2, 32, 10, 10)
    # each distinct image once (a scene's I_start recurs in each of its episodes), yet every record its own features
    images = load_answering_records(store)
    distinct = {image_digest(x) for x in torch.cat([images[keys.FIRST_RGB], images[keys.LAST_RGB]])}
    assert sum(seen) == 2 * len(distinct) < 2 * 2 * records.shape[0]
    one = model.encode_frames(images[keys.LAST_RGB][-1:])
    assert torch.allclose(records[keys.LAST_FEATURES][-1, 0].float(), one[0], atol=2e-2)
    batch = Batches(records, 4, augment=True).sample()
    assert batch[keys.FIRST_FEATURES].shape == (4, 32, 10, 10) and batch[keys.FIRST_FEATURES].dtype == torch.float32
    # with a cache key the features are kept beside the store and read back, not recomputed; another key recomputes
    key, store = encoder_fingerprint(model.encoder), shutil.copytree(store, tmp_path / "store", ignore=shutil.ignore_patterns("features"))
    cached = encode_store(store, model.encode_frames, transforms=2, cache_key=key)
    assert torch.equal(cached[keys.FIRST_FEATURES], records[keys.FIRST_FEATURES]) and len(list((store / "features").iterdir())) == 1

    def fails(x):
        raise AssertionError("recomputed although cached")
    again = encode_store(store, fails, transforms=2, cache_key=key)
    assert torch.equal(again[keys.LAST_FEATURES], records[keys.LAST_FEATURES])
    with pytest.raises(AssertionError, match="recomputed"):
        encode_store(store, fails, transforms=2, cache_key="0" * 64)
    cache = next((store / "features").iterdir())
    cache.write_bytes(cache.read_bytes()[:100])                    # a damaged cache is recomputed and replaced
    assert torch.equal(encode_store(store, model.encode_frames, transforms=2, cache_key=key)[keys.FIRST_FEATURES],
                       records[keys.FIRST_FEATURES])
    assert torch.equal(encode_store(store, fails, transforms=2, cache_key=key)[keys.FIRST_FEATURES], records[keys.FIRST_FEATURES])
    other = VQAModel(small_dataset.vocab.itos, small_dataset.answers)
    assert encoder_fingerprint(other.encoder) != key


def _steps(run, name):
    with open(run / "csv" / "scalars" / f"{name}.csv") as f:
        return [int(float(row[0])) for row in csv.reader(f)]


def test_pretrain_and_train_vqa_recipes_write_log_and_resume(small_dataset, answering_root):
    root, overrides = answering_root
    quiet = ["logger=csv", "logger.progress=false"]
    pretrain = load_recipe("pretrain")
    summary = pretrain.pretrain(compose_recipe_config("pretrain", ["part=vqa_encoder",
        *overrides, *quiet, "train.steps=2", "train.batch_size=2", "train.eval_interval=1", "frames.max_frames=8"]))
    assert (root / "encoder" / "encoder.pt").exists() and summary["steps"] == 2
    train_vqa = load_recipe("train_vqa")
    run = root / "vqa" / "resume-test" / "random"           # its own folder: other tests train eqa VQAs of random too
    args = [*overrides, *quiet, "system=random", "vqa=eqa", "train.batch_size=4", "train.eval_interval=3",
            "checkpoint.interval_steps=3", f"out_dir={run}"]
    first = train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=6"]))
    assert first["steps"] == 6 and (run / "vqa.pt").exists() and (run / "config.yaml").exists()
    with pytest.raises(FileExistsError, match="resume=true"):
        train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=6"]))
    again = train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=9", "resume=true"]))
    assert again["steps"] == 9
    assert _steps(run, "train/loss") == [3, 6, 9]                        # continued, nothing logged twice
    with pytest.raises(ValueError, match="train.select: 'loss' -> 'accuracy'"):   # kept by loss: resumed by loss only
        train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=12", "resume=true", "train.select=accuracy"]))
    model = load_vqa(run)
    assert model.meta["system"] == "random" and model.meta["encoder"]["frozen"] and model.answers == list(small_dataset.answers)
    assert model.meta["question_types"] == ["counting"]                  # the demo flags other types as guesses
    # a checkpoint whose files were altered is refused with what to do
    latest = sorted((run / "checkpoints").glob("checkpoint-*"))[-1]
    victim = next(p for p in (latest / "components").rglob("*") if p.is_file() and p.stat().st_size > 100)
    victim.write_bytes(victim.read_bytes()[:50])
    with pytest.raises(CheckpointCorrupt, match="delete"):
        train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=12", "resume=true"]))
    with pytest.raises(FileNotFoundError, match="collect"):
        train_vqa.train(compose_recipe_config("train_vqa", [*args, "system=privileged"]))


def _lr_rows(run):
    with open(run / "csv" / "scalars" / "train" / "lr.csv") as f:
        return [float(row[1]) for row in csv.reader(f)]


def test_train_vqa_refuses_test_rollouts_bad_sizes_changed_resumes_dead_runs_and_a_second_writer(small_dataset,
                                                                                                answering_root, tmp_path):
    from mqa_rl.training.run_dir import RunLock

    root, overrides = answering_root
    train_vqa = load_recipe("train_vqa")
    args = [*overrides, "logger=csv", "logger.progress=false", "system=random", "vqa=eqa", "encoder.weights=null",
            "encoder.freeze=false", "train.batch_size=4", "train.eval_interval=2", "checkpoint.interval_steps=2",
            "train.val_fraction=0"]
    bad = tmp_path / "bad"
    for override, key in (("train.batch_size=7.5", "train.batch_size"), ("train.steps=0", "train.steps"),
                          ("checkpoint.interval_steps=-8", "checkpoint.interval_steps")):
        with pytest.raises(ValueError, match=key):
            train_vqa.train(compose_recipe_config("train_vqa", [*args, override, f"out_dir={bad}"]))
    assert not bad.exists()                                               # refused before anything is written
    test_rollouts = root / "rollouts" / "counting" / "random" / "test"
    with pytest.raises(ValueError, match="training split"):
        train_vqa.train(compose_recipe_config("train_vqa", [*args, f"rollouts={test_rollouts}", f"out_dir={bad}"]))
    assert not bad.exists()                                               # nor a folder of its own

    run = tmp_path / "run"
    train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=2", f"out_dir={run}"]))
    assert load_vqa(run).meta["rollouts_split"] == "train"
    with pytest.raises(ValueError, match="train.lr"):                     # a changed setting is named, not ignored
        train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=4", "resume=true", "train.lr=0.5",
                                                            f"out_dir={run}"]))
    with pytest.raises(ValueError, match="system"):                       # nor another system's rollouts
        train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=4", "resume=true",
                                                            "system=no_manipulation", f"out_dir={run}"]))
    train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=4", "resume=true", "train.lr=0.25",
                                                        "resume_allow_changes=true", f"out_dir={run}"]))
    assert _lr_rows(run) == [pytest.approx(1e-3), pytest.approx(0.25)]     # the new phase trains at its own rate
    with RunLock(run, "train_vqa.py"):                                    # a second writer is refused at once
        with pytest.raises(RuntimeError, match="another train_vqa.py run"):
            train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=6", "resume=true",
                                                                "train.lr=0.25", f"out_dir={run}"]))
    dead = tmp_path / "dead"                                              # killed before its first checkpoint
    (dead / "csv").mkdir(parents=True)
    for resume in ("false", "true"):
        with pytest.raises(FileExistsError, match="no checkpoint"):
            train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=2", f"resume={resume}",
                                                                f"out_dir={dead}"]))
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError, match="is a file"):
        train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.steps=2", f"out_dir={tmp_path / 'file'}"]))


def test_train_vqa_keeps_the_checkpoint_its_validation_metric_picks(small_dataset, answering_root, tmp_path, monkeypatch):
    _, overrides = answering_root
    train_vqa = load_recipe("train_vqa")
    # the tiny pipeline has one training scene per level, too few to hold one out: hold out every other episode
    monkeypatch.setattr(train_vqa, "scene_split", lambda records, fraction, seed: torch.arange(records.shape[0]) % 2 == 1)
    args = [*overrides, "logger=csv", "logger.progress=false", "system=random", "vqa=eqa", "encoder.weights=null",
            "encoder.freeze=false", "train.batch_size=4", "train.eval_interval=1", "train.steps=6", "train.lr=0.05"]
    for select in ("loss", "accuracy"):
        out = tmp_path / select
        summary = train_vqa.train(compose_recipe_config("train_vqa", [*args, f"train.select={select}", f"out_dir={out}"]))
        with open(out / "csv" / "scalars" / "val" / f"{select}.csv") as f:
            values = [float(row[1]) for row in csv.reader(f)]
        best = (min if select == "loss" else max)(range(len(values)), key=lambda i: values[i])  # the first best
        assert summary["selected_by"] == f"val/{select}" and summary["best_step"] == best + 1
        assert load_vqa(out).meta["step"] == best + 1
    with pytest.raises(ValueError, match="train.select"):
        train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.select=f1", f"out_dir={tmp_path / 'bad'}"]))
    # patience: a head whose val loss cannot improve (lr 0) stops 2 steps after its first evaluation, keeps that
    # checkpoint, and a resumed run knows it has finished
    still = [*args, "train.lr=0", "train.patience_steps=2", f"out_dir={tmp_path / 'still'}"]
    summary = train_vqa.train(compose_recipe_config("train_vqa", still))
    assert summary["stopped_early"] and summary["steps"] == 3 and summary["best_step"] == 1
    assert _steps(tmp_path / "still", "val/loss") == [1, 2, 3] and load_vqa(tmp_path / "still").meta["step"] == 1
    assert train_vqa.train(compose_recipe_config("train_vqa", [*still, "resume=true"]))["steps"] == 3
    again = train_vqa.train(compose_recipe_config("train_vqa", [*still, "resume=true", "train.patience_steps=null"]))
    assert again["steps"] == 6 and not again["stopped_early"]            # when to stop is free on resume: trains on
    with pytest.raises(ValueError, match="train.patience_steps"):
        train_vqa.train(compose_recipe_config("train_vqa", [*args, "train.patience_steps=0", f"out_dir={tmp_path / 'bad'}"]))


def test_frame_pack_carries_the_frames_losslessly_and_pretrains_without_the_dataset(small_dataset, answering_root, tmp_path):
    root, overrides = answering_root
    quiet = ["logger=csv", "logger.progress=false"]
    pretrain = load_recipe("pretrain")
    pack = tmp_path / "frames.xz"
    pretrain.export_pack(compose_recipe_config("pretrain", ["part=vqa_encoder", *overrides, f"export_pack={pack}",
                                                               "frames.max_frames=6"]))
    frames, meta = load_frame_pack(pack)
    expected = pretraining_frames([root / "rollouts" / "counting" / "random" / "train"], small_dataset, max_frames=6, seed=0)
    for key in (keys.RGB, keys.DEPTH, keys.OBJECT_MAP, keys.CLASS_MAP, keys.SCENE, keys.LEVEL):
        assert torch.equal(frames[key], expected[key]), key                 # bit-exact
    assert meta["classes"] == list(small_dataset.classes) and meta["camera_distance"] == small_dataset.camera.distance
    # trains from the pack alone: the dataset path points nowhere
    out = tmp_path / "encoder_from_pack"
    summary = pretrain.pretrain(compose_recipe_config("pretrain", ["part=vqa_encoder",
        *overrides, *quiet, f"frames.pack={pack}", f"dataset={tmp_path / 'no_dataset'}", f"out_dir={out}",
        "train.steps=2", "train.batch_size=2", "train.eval_interval=1"]))
    _, encoder_meta = load_encoder(out / "encoder.pt")
    assert summary["steps"] == 2 and encoder_meta["dataset_sha256"] == meta["dataset_sha256"]
    assert encoder_meta["classes"] == list(small_dataset.classes)
    # nothing half-written is taken for a pack
    broken = tmp_path / "broken.xz"
    broken.write_bytes(pack.read_bytes()[: pack.stat().st_size // 2])
    with pytest.raises(ValueError, match="export_pack"):
        load_frame_pack(broken)
    with pytest.raises(FileNotFoundError, match="export_pack"):
        load_frame_pack(tmp_path / "none.xz")


def test_encoder_head_width_gives_the_heads_context_and_the_vqa_takes_the_files_architecture(small_dataset, tmp_path):
    torch.manual_seed(0)
    k = 1 + len(small_dataset.classes)
    encoder = FrameEncoder((8, 16, 32, 32), num_classes=k, head_width=16)
    x = torch.randn(2, 3, 224, 224)
    maps = encoder.class_maps(x)
    assert maps.shape == (2, 2 * k, 24, 24) and bool((maps[:, k:] >= 0).all())    # log-probs, then densities ≥ 0
    mid, bottleneck = encoder.features(x)
    torch.testing.assert_close(encoder.heads_of(mid, bottleneck)[1], encoder.heads_of(mid)[1])
    path = save_encoder(encoder, tmp_path / "encoder.pt", {"classes": list(small_dataset.classes)})
    again, _ = load_encoder(path)
    assert again.head_width == 16
    torch.testing.assert_close(again.eval().class_maps(x), encoder.eval().class_maps(x))
    cfg = compose_recipe_config("train_vqa", [f"dataset={small_dataset.root}", f"encoder.weights={path}", "vqa=classes"])
    model, _ = build_model(cfg, small_dataset)
    assert model.config["encoder_head_width"] == 16
    torch.testing.assert_close(model.encoder.eval().class_maps(x), encoder.class_maps(x))


def test_density_targets_spread_by_a_gaussian_keep_their_mass(small_dataset):
    k = 1 + len(small_dataset.classes)
    loss = EncoderPretrainLoss(FrameEncoder(num_classes=k), PretrainHeads(32, k), camera_distance=2.0, density_sigma=1.0)
    delta = torch.zeros(1, k, 24, 24)
    delta[0, 3, 12, 12] = 1.0
    spread = loss.blur(delta)
    assert abs(float(spread.sum()) - 1.0) < 1e-5 and float(spread[0, 3, 12, 12]) < 0.2
    assert float(spread[0, 3, 12, 13]) == pytest.approx(float(spread[0, 3, 13, 12]))   # isotropic
    plain = EncoderPretrainLoss(FrameEncoder(num_classes=k), PretrainHeads(32, k), camera_distance=2.0)
    assert torch.equal(plain.blur(delta), delta)


def test_pretraining_frames_mix_stores_of_another_dataset_of_the_same_objects(small_dataset, answering_root,
                                                                              sparse_dataset, tmp_path):
    """More scenes to learn to see from: a store collected on another dataset (same object library) is read
    with its own scenes, its scene ids kept apart; a store whose dataset is gone is refused, saying why."""
    import json

    from mqa_rl.training.vqa_data import SCENE_OFFSET

    root, _ = answering_root
    main_store = root / "rollouts" / "counting" / "no_manipulation" / "train"
    other = tmp_path / "other"
    collect = load_recipe("collect")
    collect.collect(compose_recipe_config("collect", ["what=rollouts",
        f"root={other}", f"dataset={sparse_dataset.root}", "system=no_manipulation", "splits=[train]",
        "questions.max_per_group.train=1", "collection.workers=1", "progress=false"]))
    other_store = other / "rollouts" / "counting" / "no_manipulation" / "train"
    frames = pretraining_frames([main_store, other_store], small_dataset)
    scenes = frames[keys.SCENE]
    extra = frames[scenes >= SCENE_OFFSET]
    assert len(extra) == 1 and len(frames) == len(pretraining_frames([main_store], small_dataset)) + 1
    objects = sparse_dataset.scenes[int(extra[keys.SCENE][0]) - SCENE_OFFSET].objects
    object_map, class_map = extra[keys.OBJECT_MAP][0], extra[keys.CLASS_MAP][0]
    for slot in object_map.unique().tolist():                 # labelled with the other dataset's objects
        if slot:
            label = int(class_map[object_map == slot][0])
            assert small_dataset.classes[label - 1] == objects[slot - 1].class_name
    moved = tmp_path / "moved"
    shutil.copytree(other_store, moved)
    meta = json.loads((moved / "meta.json").read_text())
    meta["dataset"]["manifest_sha256"] = "0" * 64
    (moved / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="make it again"):
        pretraining_frames([main_store, moved], small_dataset)


def test_grounding_loss_teaches_the_classes_pool_which_class_a_question_names(small_dataset, answering_root, tmp_path):
    """Learnt from answers alone the classes pool's choice stayed near uniform; the grounding loss
    supervises it with the classes the question names (head h <-> the h-th class; -1 = none)."""
    from mqa_rl.modules.answering.vqa import grounding_module
    from mqa_rl.training.vqa_data import load_answering_records, question_class_labels

    root, _ = answering_root
    records = load_answering_records(root / "rollouts" / "counting" / "random" / "train", images=False)
    labels = question_class_labels(records, small_dataset)
    for row, q in zip(labels.tolist(), records[keys.QUESTION_ID].tolist()):     # COUNTING: one class, then none
        assert small_dataset.classes[row[0] - 1] == small_dataset.questions[q].classes[0] and row[1] == -1
    torch.manual_seed(0)
    k = 1 + len(small_dataset.classes)
    questions = [q for q in small_dataset.questions if q.type == "counting"][:40]
    model = VQAModel(small_dataset.vocab.itos, small_dataset.answers, pool="classes", dropout=0.0, encoder_classes=k)
    n = len(questions)
    maps = torch.randn(n, 2 * k, 24, 24)
    batch = TensorDict({keys.QUESTION: model.tokenize([q.text for q in questions]),
                        keys.FIRST_FEATURES: maps, keys.LAST_FEATURES: maps,
                        keys.ANSWER_LABEL: torch.tensor([small_dataset.answers.index(q.answer) for q in questions]),
                        keys.QUESTION_CLASSES: torch.tensor([[1 + small_dataset.classes.index(q.classes[0]), -1]
                                                             for q in questions])}, batch_size=[n])
    loss = VQALoss(vqa_module(model, from_features=True), grounding=grounding_module(model), grounding_weight=1.0)
    optim = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=3e-3)
    with torch.no_grad():
        first = loss(batch)
    assert {"loss_vqa", "loss_grounding", "grounding_accuracy"} <= set(first.keys())
    for _ in range(150):
        out = loss(batch)
        optim.zero_grad()
        sum(v for key, v in out.items() if key.startswith("loss_")).backward()
        optim.step()
    with torch.no_grad():
        last = loss(batch)
        choice = model.grounding_logits(batch[keys.QUESTION])[:, 0].argmax(-1)
    assert float(last["loss_grounding"]) < 0.3 * float(first["loss_grounding"])
    assert float(last["grounding_accuracy"]) == 1.0 and torch.equal(choice, batch[keys.QUESTION_CLASSES][:, 0])
    none = batch.clone()
    none.set(keys.QUESTION_CLASSES, torch.full((n, 2), -1))                     # no class named: no grounding term
    assert float(loss(none)["loss_grounding"].detach()) == 0.0
    with pytest.raises(KeyError, match="question_class_labels"):
        loss(batch.exclude(keys.QUESTION_CLASSES))
    with pytest.raises(ValueError, match="pool='classes'"):
        VQAModel(small_dataset.vocab.itos, small_dataset.answers, pool="eqa").grounding_logits(batch[keys.QUESTION])
    # the recipe: vqa=classes trains with the grounding term and logs its accuracy
    encoder = save_encoder(FrameEncoder(num_classes=k), tmp_path / "encoder.pt", {"classes": list(small_dataset.classes)})
    _, overrides = answering_root
    train_vqa = load_recipe("train_vqa")
    out = tmp_path / "vqa"
    train_vqa.train(compose_recipe_config("train_vqa", [
        *overrides, "logger=csv", "logger.progress=false", "system=random", "vqa=classes", f"out_dir={out}",
        f"encoder.weights={encoder}", "train.steps=2", "train.batch_size=4", "train.eval_interval=2", "train.augment=false"]))
    assert _steps(out, "train/grounding_accuracy") == [2]
