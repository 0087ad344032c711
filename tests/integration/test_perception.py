"""The counting perception: its targets, the vote counting, its file, and the VQA that reads it."""

from types import SimpleNamespace

import cv2
import pytest
import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.perception_frames import check_disjoint, scene_fingerprint
from mqa_rl.collectors.store import load_records
from mqa_rl.losses.perception import (PerceptionLoss, countable_counts, crop_counts, perception_targets, random_crop,
                                     slot_pixels)
from mqa_rl.modules.answering import vote_counting
from mqa_rl.modules.answering.perception import CountingPerception, init_from_file, load_perception, save_perception
from mqa_rl.modules.answering.vqa_ensemble import VQAEnsemble
from mqa_rl.modules.answering.vqa import VQAModel, load_vqa, save_vqa
from mqa_rl.training.count_calibration import count_accuracy_table
from mqa_rl.transforms.episode_stats import COUNTABLE_PX

K = 8          # classes incl. background in these synthetic frames
K_SHIPPED = 21  # the dataset's 20 classes + the bin


def synthetic_frame():
    """A 112-px object map where class 3 has two touching objects (one blob of a class mask) and a tiny
    one below the counting line, class 5 one object cut in two by an occluder of class 7."""
    omap = torch.zeros(112, 112, dtype=torch.uint8)
    omap[10:40, 10:30] = 1          # class 3
    omap[10:40, 30:50] = 2          # class 3, touching slot 1
    omap[60:70, 10:70] = 3          # class 5 ...
    omap[55:75, 35:45] = 4          # ... cut in two by class 7
    omap[100:102, 100:102] = 5      # class 3, 4 px at 112 = 16 px of the 224-px render: not countable
    classes = torch.zeros(50, dtype=torch.int64)
    classes[:5] = torch.tensor([3, 3, 5, 7, 3])
    visible = torch.zeros(50)
    visible[:5] = torch.stack([(omap == i + 1).sum() * 4.0 for i in range(5)])
    return omap, classes, visible


def test_perfect_class_fractions_and_votes_count_instances_not_blobs():
    omap, classes, visible = synthetic_frame()
    frac, offsets, _, density = perception_targets(omap[None], classes[None], visible[None], K, 56)
    assert torch.allclose(frac.sum(1), torch.ones(1, 56, 56))
    # the class fractions hold each class's visible area: 16 px of the render per output cell
    area3 = frac[0, 3].sum() * 16
    assert area3 == pytest.approx(float(visible[[0, 1, 4]].sum()), rel=1e-5)
    truth = {c: int(((classes == c) & (visible >= COUNTABLE_PX)).sum()) for c in range(1, K)}
    for readout in vote_counting.READOUTS:
        counted = vote_counting.counts(frac, offsets, density, 16.0, readout=readout)[0]
        assert counted.tolist() == [truth[c] for c in range(1, K)], readout
        assert counted[2].item() == 2 and counted[4].item() == 1, readout   # classes 3 and 5
    with pytest.raises(ValueError, match="unknown readout"):
        vote_counting.counts(frac, offsets, density, 16.0, readout="blobs")


def test_the_density_holds_a_unit_mass_per_countable_object_only():
    omap, classes, visible = synthetic_frame()
    *_, density = perception_targets(omap[None], classes[None], visible[None], K, 56)
    # four countable objects (the two halves of the cut one are one object); the 16-px one has no mass
    assert float(density.sum()) == pytest.approx(4.0, rel=1e-5)
    assert float(density[0, 0, 50, 50]) == 0.0                       # the tiny object's cell (100:102 at 112 px)
    assert float(density[0, 0, 10, 8]) == pytest.approx(1 / 150)    # slot 1: 30 x 20 px at 112 = 150 cells
    assert countable_counts(visible[None], classes[None], K)[0].tolist() == [0, 0, 2, 0, 1, 0, 1]


def test_count_accuracy_scores_the_classes_present_in_each_frames_scene_by_level():
    """A (frame, class) pair counts when the class is in the frame's scene: right where the count equals the
    objects with >= 20 visible px, absent classes left out, every level apart."""
    from tensordict import TensorDict

    classes = torch.zeros(2, 50, dtype=torch.long)
    classes[:, :3] = torch.tensor([1, 1, 2])                 # two of class 1, one of class 2 in both frames
    visible = torch.zeros(2, 50)
    visible[:, :3] = torch.tensor([[30.0, 30.0, 5.0], [30.0, 10.0, 25.0]])
    frames = TensorDict({keys.OBJECT_CLASSES: classes, keys.FRAME_VISIBLE: visible,
                         keys.LEVEL: torch.tensor([0, 2])}, batch_size=[2])
    pred = torch.zeros(2, K - 1, dtype=torch.long)
    pred[0, 0], pred[1, 0], pred[1, 1] = 2, 2, 1            # frame 0 right twice; frame 1 once (class 1 shows 1)
    table = count_accuracy_table(pred, frames)
    assert table == {"val/count_accuracy": 0.75, "val/count_accuracy_easy": 1.0, "val/count_accuracy_hard": 0.5}


def test_a_crops_targets_are_the_whole_frames_targets_cropped():
    """Training on crops (train.crop): a cut object keeps the whole frame's mass per cell and counts by the share of
    its pixels inside, so the crop's density and count targets are the whole frame's, cropped."""
    omap, classes, visible = synthetic_frame()
    rgb = torch.randint(0, 256, (1, 3, 112, 112), dtype=torch.uint8)
    frac, _, _, density = perception_targets(omap[None], classes[None], visible[None], K, 56)
    torch.manual_seed(3)
    for _ in range(5):
        (rgb_c, omap_c), slot_area = random_crop(48, rgb, omap[None])
        assert rgb_c.shape == (1, 3, 48, 48) and omap_c.shape == (1, 48, 48)
        hits = [(y, x) for y in range(0, 65, 2) for x in range(0, 65, 2) if torch.equal(rgb[0, :, y:y + 48, x:x + 48], rgb_c[0])]
        assert len(hits) == 1
        y, x = hits[0]
        assert torch.equal(omap_c[0], omap[y:y + 48, x:x + 48])
        frac_c, _, _, density_c = perception_targets(omap_c, classes[None], visible[None], K, 24, slot_area)
        assert torch.allclose(density_c, density[..., y // 2:y // 2 + 24, x // 2:x // 2 + 24])
        assert torch.allclose(frac_c, frac[..., y // 2:y // 2 + 24, x // 2:x // 2 + 24])
        inside = torch.stack([(omap_c[0] == i + 1).sum() for i in range(50)]).float()[None]
        assert torch.equal(slot_pixels(omap_c), inside)
        counted = crop_counts(visible[None], classes[None], K, inside, slot_area)
        assert float(counted.sum()) == pytest.approx(float(density_c.sum()), rel=1e-5)   # each object's share, once
        assert 0 <= float(counted.sum()) <= 4 + 1e-5
    # the whole frame as its own crop: the perfect counter's counts
    whole = torch.stack([(omap == i + 1).sum() for i in range(50)]).float()[None]
    assert crop_counts(visible[None], classes[None], K, whole, whole).tolist() == countable_counts(visible[None], classes[None], K).tolist()


def test_count_features_put_the_image_row_first_and_one_hot_the_count():
    omap, classes, visible = synthetic_frame()
    frac, offsets, _, density = perception_targets(omap[None], classes[None], visible[None], K, 56)
    feats = vote_counting.count_features(frac, offsets, density, 16.0)
    assert feats.shape == (1, K, vote_counting.FEATURES)
    assert feats[0, 3, 2] == 1.0 and feats[0, 3, :vote_counting.MAX_COUNT + 1].sum() == 1.0
    assert feats[0, 3, -1] == pytest.approx(2.0, abs=1e-4)          # the expected count read from the density
    assert feats[0, 0, 0] == pytest.approx(4 / 50)                   # 2 + 1 + 1 countable objects
    assert feats[0, 1, 0] == 1.0                                     # an absent class counts 0


def test_perception_learns_a_few_frames():
    torch.manual_seed(0)
    omap, classes, visible = synthetic_frame()
    model = CountingPerception(K, widths=(8, 8, 16, 16))
    loss = PerceptionLoss(model)
    rgb = torch.zeros(2, 3, 112, 112)
    rgb[:, 0] = omap.float() / 5.0 - 0.5          # each object its own shade of red
    rgb[:, 1] = (torch.tensor([0, 3, 3, 5, 7, 3])[omap.long()].float() / 7.0) - 0.5
    batch = TensorDict({keys.OBJECT_MAP: omap.expand(2, -1, -1), keys.OBJECT_CLASSES: classes.expand(2, -1),
                        keys.FRAME_VISIBLE: visible.expand(2, -1)}, batch_size=[2])
    optim = torch.optim.Adam(model.parameters(), lr=3e-3)
    first = None
    for _ in range(60):
        td = loss(batch, rgb)
        total = loss.total(td)
        first = float(total) if first is None else first
        optim.zero_grad()
        total.backward()
        optim.step()
    assert float(total.detach()) < 0.4 * first


def test_perception_file_round_trip_and_refusals(tmp_path):
    model = CountingPerception(K, widths=(8, 8, 16, 16))
    path = save_perception(model, tmp_path / "perception.pt", {"command": "test"})
    loaded, meta = load_perception(path)
    x = torch.randint(0, 255, (1, 3, 224, 224), dtype=torch.uint8)
    assert torch.equal(loaded.predict(x)[0], model.eval().predict(x)[0]) and meta["command"] == "test"
    with pytest.raises(FileNotFoundError, match="train_perception.py"):
        load_perception(tmp_path / "missing.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="cannot be read"):
        load_perception(tmp_path / "junk.pt")
    torch.save({"format": "something else"}, tmp_path / "foreign.pt")
    with pytest.raises(ValueError, match="not a perception file"):
        load_perception(tmp_path / "foreign.pt")
    blob = torch.load(path, weights_only=True)                         # crafted files: refused before allocating
    nan = {**blob, "state_dict": {k: v.clone() for k, v in blob["state_dict"].items()}}
    next(v for v in nan["state_dict"].values() if v.is_floating_point()).fill_(float("nan"))
    torch.save(nan, tmp_path / "nan.pt")
    with pytest.raises(ValueError, match="NaN or infinity"):
        load_perception(tmp_path / "nan.pt")
    torch.save({**blob, "config": {**blob["config"], "counting": {"radius": float("nan")}}}, tmp_path / "nan_counting.pt")
    with pytest.raises(ValueError, match="radius=nan is not a finite number"):
        load_perception(tmp_path / "nan_counting.pt")
    torch.save({**blob, "config": {**blob["config"], "widths": [8, 8, 16, 10**7]}}, tmp_path / "huge.pt")
    with pytest.raises(ValueError, match=r"widths\[3\]=10000000 is not a size"):
        load_perception(tmp_path / "huge.pt")


def test_a_perception_of_another_object_library_is_refused_at_load_by_its_readers(small_dataset, tmp_path):
    from mqa_rl.modules.answering.kept_frame import FrameKeeper

    other = save_perception(CountingPerception(1 + 4, widths=(8, 8, 16, 16)), tmp_path / "four.pt", {})
    with pytest.raises(ValueError, match=r"knows 4 classes, the dataset 20: train one"):
        FrameKeeper.from_file(other, small_dataset)           # evaluate_policy kept_frame=, fit_stop perception=


def test_counting_vqa_answers_through_the_public_contract_and_reloads(tmp_path):
    perception = CountingPerception(K, widths=(8, 8, 16, 16))
    vocab = ["<pad>", "<unk>", "how", "many", "cans", "are", "there", "in", "the", "bin", "?"]
    model = VQAModel(vocab, ["0", "1", "2", "3"], pool="counts", cell_heads=2, perception=perception.config())
    model.encoder.load_state_dict(perception.state_dict())
    tokens = model.tokenize(["How many cans are there in the bin?"])
    img = torch.randint(0, 255, (1, 224, 224, 3), dtype=torch.uint8)
    probs = model.answer_probs(tokens, img, img)
    assert probs.shape == (1, 4) and torch.allclose(probs.sum(-1), torch.ones(1))
    same_words = dict(vocab=SimpleNamespace(itos=vocab), answers=["0", "1", "2", "3"], root="ds")
    model.check_dataset(SimpleNamespace(classes=[f"c{i}" for i in range(K - 1)], **same_words))
    with pytest.raises(ValueError, match=f"knows {K - 1} classes, the dataset 20"):   # another object library
        model.check_dataset(SimpleNamespace(classes=[f"c{i}" for i in range(20)], **same_words))
    # repeated images (I_stop = I_start, a scene's I_start in several episodes) are encoded once, answered as alone
    other = torch.randint(0, 255, (1, 224, 224, 3), dtype=torch.uint8)
    first, last = torch.cat([img, img, other]), torch.cat([other, img, img])
    together = model.answer_probs(tokens.expand(3, -1), first, last)
    alone = torch.cat([model.answer_probs(tokens, first[i:i + 1], last[i:i + 1]) for i in range(3)])
    assert torch.allclose(together, alone, atol=1e-5) and torch.allclose(together[1], probs[0], atol=1e-5)
    assert model.grounding_logits(tokens).shape == (1, 2, K)
    again = load_vqa(save_vqa(model, tmp_path / "vqa.pt"))
    assert torch.allclose(again.answer_probs(tokens, img, img), probs)
    blob = torch.load(tmp_path / "vqa.pt", weights_only=True)
    next(v for v in blob["state_dict"].values() if v.is_floating_point()).fill_(float("inf"))
    torch.save(blob, tmp_path / "inf.pt")
    with pytest.raises(ValueError, match="NaN or infinity"):          # a crafted file would answer nonsense silently
        load_vqa(tmp_path / "inf.pt")
    with pytest.raises(ValueError, match="counting perception"):
        VQAModel(vocab, ["0"], pool="counts")
    # the frames it reads in full: its perception's input (a 448-px perception wants the answer camera's frames)
    fine = VQAModel(vocab, ["0", "1", "2", "3"], pool="counts", cell_heads=2,
                    perception=CountingPerception(K, widths=(8, 8, 16, 16), image_size=448).config())
    assert model.frame_size == 112 and fine.frame_size == 448 and VQAModel(vocab, ["0"]).frame_size is None
    with pytest.raises(ValueError, match="frames of different sizes"):
        VQAEnsemble([again, load_vqa(save_vqa(fine, tmp_path / "fine.pt"))])
    # seeds of a head on one frozen perception answer together from one pass of it, as each alone would
    seed1 = VQAModel(vocab, ["0", "1", "2", "3"], pool="counts", cell_heads=2, perception=perception.config())
    seed1.encoder.load_state_dict(perception.state_dict())
    seed1 = load_vqa(save_vqa(seed1, tmp_path / "seed1.pt"))
    pair = VQAEnsemble([again, seed1])
    alone = (again.answer_probs(tokens, img, img) + seed1.answer_probs(tokens, img, img)) / 2
    assert pair.shared_encoder and torch.allclose(pair.answer_probs(tokens, img, img), alone, atol=1e-6)
    scratch = VQAModel(vocab, ["0", "1", "2", "3"], pool="counts", cell_heads=2, perception=perception.config())
    mixed = VQAEnsemble([again, load_vqa(save_vqa(scratch, tmp_path / "scratch.pt"))])
    assert not mixed.shared_encoder and mixed.feature_reader is None
    # whose features evaluate.py caches per store: a counting head's, one perception's seeds' (not EQA's maps)
    assert again.feature_reader is again and pair.feature_reader is pair.members[0] and VQAModel(vocab, ["0"]).feature_reader is None


def test_a_fine_tuned_counting_vqa_reads_the_frozen_numbers_and_sends_gradients_to_density_and_classes():
    """Fine-tuning starts exactly where the frozen head stood (same features in value), and the answer loss
    reaches the perception's density and class heads (straight through the count one-hot), not its votes."""
    torch.manual_seed(0)
    perception = CountingPerception(K, widths=(8, 8, 16, 16)).eval()
    img = torch.randint(0, 255, (3, 3, 224, 224), dtype=torch.uint8)
    frozen = perception.count_features(img)
    features = perception.count_features(img, trainable=True)
    assert torch.allclose(features, frozen, atol=1e-5) and features.requires_grad
    (features[:, 1:, : vote_counting.MAX_COUNT + 1] * torch.randn(3, K - 1, vote_counting.MAX_COUNT + 1)).sum().backward()
    assert perception.density.weight.grad.abs().sum() > 0 and perception.classes.weight.grad.abs().sum() > 0
    assert perception.votes.weight.grad is None
    vocab = ["<pad>", "<unk>", "how", "many", "cans", "?"]
    model = VQAModel(vocab, ["0", "1"], pool="counts", cell_heads=2, perception=perception.config(), freeze_encoder=False)
    model.train()
    assert not model.encoder.training and all(p.requires_grad for p in model.encoder.parameters())   # BN statistics kept
    assert model.encode_frames(img).requires_grad                   # the answer loss reaches the perception


def _dataset(root, scenes):
    return SimpleNamespace(root=root, scenes=[SimpleNamespace(id=i, split=s, objects=objs) for i, s, objs in scenes])


def test_a_pretraining_set_sharing_a_scene_with_the_test_split_is_refused():
    obj = lambda name, x: SimpleNamespace(name=name, pose=(x, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0))   # noqa: E731
    test_pile = [obj("can_0", 0.01), obj("apple_1", 0.05)]
    evaluation = _dataset("data/mqa", [("scene_000", "train", [obj("can_0", 0.02)]), ("scene_001", "test", test_pile)])
    fresh = _dataset("data/frames", [("scene_000", "train", [obj("can_0", 0.03)])])
    check_disjoint(fresh, [(evaluation, "test")])
    shared = _dataset("data/frames", [("scene_007", "train", list(reversed(test_pile)))])
    assert scene_fingerprint(shared.scenes[0]) == scene_fingerprint(evaluation.scenes[1])
    with pytest.raises(ValueError, match="scene_001"):
        check_disjoint(shared, [(evaluation, "test")])
    check_disjoint(_dataset("data/frames", [("s", "train", [obj("can_0", 0.02)])]), [(evaluation, "test")])


def test_a_finer_render_sees_the_same_rest_pile_and_keeps_areas_in_224_px_units(small_dataset):
    """collect.py what=frames render=448: the same rest pile as the env's 224-px render, its object map twice as fine and
    each object's visible area counted in 224-px pixels (the counting rule's), within the resampling."""
    from mqa_rl.collectors.perception_frames import collect_perception_frames, pile_episode, scene_questions
    from mqa_rl.envs.sapien_bin import SapienBinEnv

    qid = scene_questions(small_dataset)[small_dataset.scenes[0].id]
    frames = {}
    for render in (224, 448):
        env = SapienBinEnv(small_dataset, split=None, max_pushes=1, image_size=render)
        frames[render] = pile_episode(env, 0, qid, pushes=0, size=render, seed=0, slot=0)[0]
        env.close()
    coarse, fine = frames[224], frames[448]
    assert fine.get(keys.RGB).shape[-1] == fine.get(keys.OBJECT_MAP).shape[-1] == 448
    assert (fine.get(keys.OBJECT_MAP)[::2, ::2] != coarse.get(keys.OBJECT_MAP)).float().mean() < 0.02
    a, b = coarse.get(keys.FRAME_VISIBLE), fine.get(keys.FRAME_VISIBLE)
    big = a >= 100
    assert big.sum() >= 3 and ((b[big] - a[big]).abs() / a[big]).max() < 0.15
    with pytest.raises(ValueError, match="render must be a multiple"):
        collect_perception_frames("unused", small_dataset, episodes_per_scene=1, pushes=0, size=224, render=300)


def test_frames_perception_and_counting_vqa_recipes_end_to_end(small_dataset, sparse_dataset, answering_root, tmp_path):
    """collect.py what=frames (resumable, refuses the test split's piles) → train_perception (resumes, refuses
    changed settings) → train_vqa vqa=counting → load_vqa answers."""
    from conftest import compose_recipe_config, load_recipe

    root, overrides = answering_root
    quiet = ["logger=csv", "logger.progress=false"]
    frames = tmp_path / "frames"
    collect = load_recipe("collect")
    args = [f"dataset={small_dataset.root}", f"out_dir={frames}", "episodes_per_scene=1", "pushes=1", "workers=1",
            "chunk_episodes=2", f"protected=[{{dataset: {sparse_dataset.root}, split: null}}]"]
    collect.main.__wrapped__(compose_recipe_config("collect", ["what=frames", *args]))
    records = load_records(frames)
    n = len(small_dataset.scenes)
    assert records.shape[0] == 2 * n and records.get(keys.RGB).shape[-1] == 112
    assert records.get(keys.PUSHES).tolist() == [0, 1] * n
    depth = records.get(keys.DEPTH)                                    # the depth image, resized as the rgb
    assert depth.dtype == torch.float16 and depth.shape[1:] == (1, 112, 112) and (depth > 0).all()
    sizes = torch.tensor([len(small_dataset.scenes[int(i)].objects) for i in records.get(keys.SCENE)])
    assert ((records.get(keys.OBJECT_CLASSES) > 0).sum(-1) == sizes).all()
    assert ((records.get(keys.FRAME_VISIBLE) > 0).sum(-1) <= sizes).all()
    with pytest.raises(ValueError, match="same pile"):
        collect.main.__wrapped__(compose_recipe_config("collect", ["what=frames",
            f"dataset={small_dataset.root}", f"out_dir={tmp_path / 'leak'}", "workers=1",
            f"protected=[{{dataset: {small_dataset.root}, split: test}}]"]))
    assert not (tmp_path / "leak").exists()

    train = load_recipe("train_perception")
    out = tmp_path / "perception"
    targs = [*quiet, f"frames.stores=[{frames}]", f"out_dir={out}", "model.widths=[8,8,16,16]", "train.batch_size=2",
             "train.eval_interval=2", "checkpoint.interval_steps=2", "train.val_fraction=0.4", "train.warmup_steps=1"]
    with pytest.raises(ValueError, match="size=224"):                 # the detail path needs full-size frames
        train.train(compose_recipe_config("train_perception", [*targs, "train.steps=2", "model.detail=4"]))
    with pytest.raises(ValueError, match="size=224"):                 # so does the ImageNet backbone
        train.train(compose_recipe_config("train_perception", [*targs, "train.steps=2", "model.backbone=efficientnet_lite0"]))
    with pytest.raises(ValueError, match="model.backbone=efficientnet_lite0"):
        train.train(compose_recipe_config("train_perception", [*targs, "train.steps=2", "model.imagenet=true"]))
    assert not (out / "checkpoints").exists()
    first = train.train(compose_recipe_config("train_perception", [*targs, "train.steps=2"]))
    assert first["steps"] == 2 and (out / "perception.pt").exists()
    maps = sorted((out / "media").glob("val_perception_maps_*.png"))  # render | classes | density of the held-out frames
    assert [m.name for m in maps] == ["val_perception_maps_0000002.png"]
    shown = cv2.imread(str(maps[0]))
    assert shown.shape[1] == 3 * shown.shape[0] // min(4, int(first["val_frames"])) and shown.std() > 0
    with pytest.raises(FileExistsError, match="resume=true"):
        train.train(compose_recipe_config("train_perception", [*targs, "train.steps=2"]))
    with pytest.raises(ValueError, match="train.lr"):
        train.train(compose_recipe_config("train_perception", [*targs, "train.steps=4", "resume=true", "train.lr=0.5"]))
    from mqa_rl.training.run_dir import RunLock

    with RunLock(out, "train_perception.py"):                         # a second writer is refused at once
        with pytest.raises(RuntimeError, match="another train_perception.py run is writing"):
            train.train(compose_recipe_config("train_perception", [*targs, "train.steps=4", "resume=true"]))
    again = train.train(compose_recipe_config("train_perception", [*targs, "train.steps=4", "resume=true"]))
    assert again["steps"] == 4 and 0.0 <= again["calibrated_val_count_accuracy"] <= 1.0
    model, meta = load_perception(out / "perception.pt")               # killed while calibrating: the best file
    save_perception(model, out / "perception.pt", {k: v for k, v in meta.items() if k != "counting_calibration"})
    (out / "summary.json").unlink()                                   # without its calibration, no summary
    finished = train.train(compose_recipe_config("train_perception", [*targs, "train.steps=4", "resume=true"]))
    assert finished == again and "counting_calibration" in load_perception(out / "perception.pt")[1]
    with pytest.raises(ValueError, match="unet only"):
        train.train(compose_recipe_config("train_perception", [*targs, "train.steps=2", "model.depth=true",
                                                               "model.backbone=efficientnet_lite0"]))
    with_depth = train.train(compose_recipe_config("train_perception", [              # the depth arm of the ablation
        *(a for a in targs if not a.startswith("out_dir=")), "train.steps=2", "model.depth=true", f"out_dir={tmp_path / 'rgbd'}"]))
    assert load_perception(with_depth["perception"])[0].depth
    with pytest.raises(ValueError, match="train.crop=40"):            # a window the U-Net's strides cannot tile
        train.train(compose_recipe_config("train_perception", [*targs, "train.steps=2", "train.crop=40"]))
    cropped = train.train(compose_recipe_config("train_perception", [                 # trained on 64-px windows
        *(a for a in targs if not a.startswith("out_dir=")), "train.steps=2", "train.crop=64", f"out_dir={tmp_path / 'crop'}",
        f"baseline={out / 'perception.pt'}"]))                                     # beside the first run's file
    assert load_perception(cropped["perception"])[0].out_size == 56                  # it reads whole frames
    # the same held-out frames, calibrated the same way: the first run's own figure, and its levels
    assert cropped["baseline_calibrated_val_count_accuracy"] == pytest.approx(again["calibrated_val_count_accuracy"])
    assert cropped["baseline_by_level"] and set(cropped["baseline_by_level"]) <= {"easy", "medium", "hard"}
    with pytest.raises(ValueError, match="baseline=.*with depth"):     # a file of another input cannot be compared
        train.train(compose_recipe_config("train_perception", [*targs, "calibrate_only=true", f"baseline={with_depth['perception']}"]))
    chosen = load_perception(out / "perception.pt")[1]["counting_calibration"]["chosen"]
    assert load_perception(out / "perception.pt")[0].counting == chosen       # the file counts with what was chosen

    train_vqa = load_recipe("train_vqa")
    vargs = [*overrides, *quiet, "system=random", "vqa=counting", f"perception.weights={out / 'perception.pt'}",
             "train.batch_size=4", "train.eval_interval=2", "train.steps=4", "checkpoint.interval_steps=2"]
    summary = train_vqa.train(compose_recipe_config("train_vqa", vargs))
    model = load_vqa(summary["vqa"])
    assert model.pool == "counts" and model.meta["encoder"]["perception"].endswith("perception.pt")
    q = small_dataset.questions[0]
    img = torch.zeros(1, 224, 224, 3, dtype=torch.uint8)
    assert model.answer_probs(model.tokenize([q.text]), img, img).shape == (1, len(small_dataset.answers))
    tuned = train_vqa.train(compose_recipe_config("train_vqa", [          # fine-tune that head with its perception
        *vargs[:-2], "train.steps=2", "encoder.freeze=false", f"init_from={summary['vqa']}", f"out_dir={tmp_path / 'ft'}"]))
    tuned_model = load_vqa(tuned["vqa"])
    assert not tuned_model.config["freeze_encoder"] and tuned_model.meta["encoder"]["init_from"] == summary["vqa"]
    assert any(not torch.equal(tuned_model.encoder.state_dict()[k], v) for k, v in model.encoder.state_dict().items())
    with pytest.raises(ValueError, match="reads depth"):            # the depth arm is not wired into the VQA
        train_vqa.train(compose_recipe_config("train_vqa", [*vargs, f"perception.weights={with_depth['perception']}",
                                                            f"out_dir={tmp_path / 'depth_vqa'}"]))
    assert not (tmp_path / "depth_vqa" / "vqa.pt").exists()
    with pytest.raises(ValueError, match="does not fit this VQA"):   # a head of another architecture
        train_vqa.train(compose_recipe_config("train_vqa", [*vargs, "vqa.dim=16", f"init_from={summary['vqa']}",
                                                            f"out_dir={tmp_path / 'bad'}"]))


@pytest.mark.parametrize("system", ["no_manipulation", "random", "dqn_student", "privileged", "privileged_countable",
                                    "dqn_countable", "dqn_countable_budget_kept"])
def test_the_shipped_counting_vqas_load_with_their_provenance_and_answer(system, small_dataset):
    """checkpoints/vqa_counting: the perception and each system's head load, match the hashes their
    provenance records, count with the calibrated settings, and answer through the public contract."""
    import hashlib
    import json

    from conftest import REPO

    folder = REPO / "checkpoints" / "vqa_counting"
    provenance = json.loads((folder / system / "provenance.json").read_text())
    assert hashlib.sha256((folder / system / "vqa.pt").read_bytes()).hexdigest() == provenance["vqa_sha256"]
    perception, meta = load_perception(folder / "perception.pt")
    assert perception.counting == meta["counting_calibration"]["chosen"]
    model = load_vqa(folder / system)
    assert model.pool == "counts" and model.meta["system"] == system and model.answers == list(small_dataset.answers)
    for name, weight in perception.state_dict().items():       # the head's frozen copy is the shipped perception
        assert torch.equal(model.encoder.state_dict()[name], weight)
    assert model.frame_size == 448                              # it reads the answer camera's frames
    frame = torch.full((1, 448, 448, 3), 128, dtype=torch.uint8)
    probs = model.answer_probs(model.tokenize(["How many cans are there in the bin?"]), frame, frame)
    assert probs.shape == (1, len(model.answers)) and torch.allclose(probs.sum(-1), torch.ones(1))


def test_the_shipped_perception_loads_with_its_provenance_and_counts_a_448_render_at_224_cells():
    """checkpoints/vqa_counting/perception.pt: its hash is its provenance's, it reads a 448-px render at one
    output cell per pixel of the 224-px render, one non-negative count per class."""
    import hashlib
    import json

    from conftest import REPO

    folder = REPO / "checkpoints" / "vqa_counting"
    provenance = json.loads((folder / "provenance.json").read_text())
    assert hashlib.sha256((folder / "perception.pt").read_bytes()).hexdigest() == provenance["perception_sha256"]
    model, meta = load_perception(folder / "perception.pt")
    assert (model.image_size, model.out_size, model.cell_px) == (448, 224, 1.0)
    assert provenance["frames"]["plan"]["render"] == 448 and meta["step"] == 1800
    counts = model.counts(torch.randint(0, 255, (1, 3, 448, 448), dtype=torch.uint8))
    assert counts.shape == (1, K_SHIPPED - 1) and (counts >= 0).all()


def test_the_detail_path_reads_the_full_render_and_warm_starts_from_a_file_without_it(tmp_path):
    torch.manual_seed(0)
    base = CountingPerception(K, widths=(8, 8, 16, 16)).eval()
    detail = CountingPerception(K, widths=(8, 8, 16, 16), detail=4)
    assert detail.input_size == 224 and detail.out_size == base.out_size == 56
    missing, unexpected = detail.load_state_dict(base.state_dict(), strict=False)
    assert not unexpected and missing and all(k.startswith("detail.") for k in missing)
    detail.eval()
    rgb = torch.randint(0, 255, (2, 3, 224, 224), dtype=torch.uint8)
    for a, b in zip(base.predict(rgb), detail.predict(rgb)):            # its last layer starts at zero
        assert torch.allclose(a, b, atol=1e-5)
    with torch.no_grad():
        detail.detail[-1].bias.fill_(1.0)
    assert not torch.allclose(base.predict(rgb)[0], detail.predict(rgb)[0], atol=1e-3)   # and it is read
    loaded, _ = load_perception(save_perception(detail, tmp_path / "p.pt", {}))
    assert loaded.detail_width == 4 and torch.equal(loaded.predict(rgb)[2], detail.predict(rgb)[2])
    with pytest.raises(ValueError, match="detail"):
        CountingPerception(K, detail=-1)


def test_the_imagenet_backbone_loads_the_wheels_weights_and_round_trips(tmp_path):
    from mqa_rl.modules.push.imagenet_backbone import imagenet_weights_path
    torch.manual_seed(0)
    scratch = CountingPerception(K, widths=(8, 8, 16, 16), backbone="efficientnet_lite0")
    assert scratch.input_size == 224 and scratch.out_size == 56 and scratch.cell_px == 16.0
    pretrained = CountingPerception(K, widths=(8, 8, 16, 16), backbone="efficientnet_lite0")
    pretrained.load_imagenet()
    blob = torch.load(imagenet_weights_path(), map_location="cpu", weights_only=True)
    assert torch.equal(pretrained.encoder.stem[0].weight, blob["_conv_stem.weight"])
    assert torch.equal(pretrained.encoder.blocks[14]._project_conv.weight, blob["_blocks.14._project_conv.weight"])
    assert not torch.equal(scratch.encoder.stem[0].weight, blob["_conv_stem.weight"])
    pretrained.eval()
    rgb = torch.randint(0, 255, (2, 3, 224, 224), dtype=torch.uint8)
    probs, votes, density = pretrained.predict(rgb)
    assert probs.shape == (2, K, 56, 56) and votes.shape == (2, 2, 56, 56) and (density >= 0).all()
    loaded, _ = load_perception(save_perception(pretrained, tmp_path / "p.pt", {}))
    assert loaded.backbone == "efficientnet_lite0" and torch.equal(loaded.predict(rgb)[2], density)
    with pytest.raises(ValueError, match="detail=0"):
        CountingPerception(K, backbone="efficientnet_lite0", detail=4)
    with pytest.raises(ValueError, match="unknown backbone"):
        CountingPerception(K, backbone="resnet")
    with pytest.raises(ValueError, match="efficientnet_lite0 only"):
        CountingPerception(K).load_imagenet()


def test_a_depth_perception_reads_the_depth_image_and_asks_for_it(tmp_path):
    torch.manual_seed(0)
    model = CountingPerception(K, widths=(8, 8, 16, 16), depth=True).eval()
    rgb = torch.randint(0, 255, (2, 3, 224, 224), dtype=torch.uint8)
    floor = torch.full((2, 1, 224, 224), 0.9)
    pile = floor.clone()
    pile[:, :, 60:120, 60:120] = 0.8                                   # an object 10 cm above the floor
    assert model.down[0][0].in_channels == 4 and model.input_size == 112
    assert not torch.allclose(model.predict(rgb, floor)[2], model.predict(rgb, pile)[2])    # depth is read
    with pytest.raises(ValueError, match="reads depth too"):
        model.predict(rgb)
    with pytest.raises(TypeError, match="float"):
        model.predict(rgb, floor.to(torch.uint8))
    loaded, _ = load_perception(save_perception(model, tmp_path / "p.pt", {}))
    assert loaded.depth and torch.equal(loaded.counts(rgb, pile), model.counts(rgb, pile))
    assert not CountingPerception(K, widths=(8, 8, 16, 16)).depth                  # rgb only by default


def test_a_depth_perception_started_from_an_rgb_file_starts_where_it_stands(tmp_path):
    """init_from an rgb file: the stem's rgb weights carried over, the depth channel's at zero, so the depth
    perception's outputs equal the rgb file's until training moves them."""
    torch.manual_seed(0)
    rgb_model = CountingPerception(K, widths=(8, 8, 16, 16)).eval()
    path = save_perception(rgb_model, tmp_path / "rgb.pt", {})
    depth_model = CountingPerception(K, widths=(8, 8, 16, 16), depth=True)
    init_from_file(depth_model, str(path))
    rgb = torch.randint(0, 255, (2, 3, 224, 224), dtype=torch.uint8)
    depth = torch.rand(2, 1, 224, 224) + 1.5
    for a, b in zip(rgb_model.predict(rgb), depth_model.eval().predict(rgb, depth)):
        assert torch.equal(a, b)
    assert depth_model.down[0][0].weight[:, 3].abs().sum() == 0
    with pytest.raises(ValueError, match="does not fit"):                     # not the other way round
        init_from_file(CountingPerception(K, widths=(8, 8, 16, 16)), str(save_perception(depth_model, tmp_path / "d.pt", {})))
