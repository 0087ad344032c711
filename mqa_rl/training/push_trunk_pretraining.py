"""The push Q-network's recognition pretrained on labelled renders, before DQN (``recipes/pretrain.py part=push_trunk``).

The paper's Q-network recognises the asked-about class with ImageNet features fine-tuned by the DQN
reward. Offline and on 2 CPU cores neither is at hand: from the reward alone the light trunk learnt
nothing about where targets are in 1,400 updates (docs/results.md, "The paper's three variants"). Here the rgb trunk and a 1×1
class head learn the class fractions of every action-grid cell from the simulator's segmentation
(``SapienBinEnv.class_cells``) on train-split renders; then the question encoder and its attention
over the classes learn which class each train-split question asks about (from the dataset's questions,
no images). ``train_dqn.py model.class_map=true model.pretrained=<out_dir>/recognition.pt`` (the ``student`` profile:
the shipped ``checkpoints/recognition/recognition.pt``) starts from them, the visual part frozen by default.

Writes ``out_dir/frames/`` (the labelled renders, reused by a rerun with the same frames.* settings),
``recognition.pt`` (the visual weights with the lowest validation loss, then the question part; written
atomically), the logger group's logs (loss, cell accuracy, per-class IoU of cells ≥ 25 % filled;
question loss and accuracy), ``summary.json``. ``init=<recognition.pt>`` starts from an earlier file
(with ``train.steps=0``: only the question phase). A killed
run keeps its frames and its best file; rerunning trains afresh from the cached frames.
"""


from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.class_frames import collect_class_frames
from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.data import MQADataset
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.files import load_memmap, write_atomic
from mqa_rl.losses.class_cells import ClassCellsLoss
from mqa_rl.modules.push.pretrained_recognition import load_recognition, save_recognition
from mqa_rl.modules.push.push_policy import make_push_qnet
from mqa_rl.training.run_logger import RunLogger
from mqa_rl.training.vqa_data import scene_split
from mqa_rl.envs.dihedral import random_dihedral_in
from mqa_rl.progress import Progress
from mqa_rl.training.seeding import seed_run

RECOGNITION_FILE = "recognition.pt"


def labelled_frames(cfg: DictConfig, dataset: MQADataset, out: Path) -> TensorDict:
    """The cached frames if they were made with these settings, else collect them (written atomically)."""
    wanted = {"count": int(cfg.frames.count), "max_pushes": int(cfg.frames.max_pushes), "split": cfg.frames.split,
              "seed": int(cfg.seed), "dataset_sha256": dataset_fingerprint(dataset.root)}
    cache = out / "frames"
    if (cache / "frames.json").exists():
        if json.loads((cache / "frames.json").read_text()) == wanted:
            try:
                return load_memmap(cache / "data", what="the cached frames", hint="collecting again").clone()
            except Exception as error:
                print(f"cached frames in {cache} unreadable ({type(error).__name__}: {error}): collecting again")
        shutil.rmtree(cache)
    env = SapienBinEnv(dataset, split=cfg.frames.split, seed=cfg.seed)
    t0 = time.perf_counter()
    frames = collect_class_frames(env, cfg.frames.count, max_pushes=cfg.frames.max_pushes, seed=cfg.seed,
                                  progress=cfg.logger.progress)
    print(f"collected {len(frames)} frames in {time.perf_counter() - t0:.0f} s", flush=True)
    tmp = out / f".frames.tmp{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    frames.memmap(tmp / "data")
    (tmp / "frames.json").write_text(json.dumps(wanted, indent=1))
    os.replace(tmp, cache)
    return frames


@torch.no_grad()
def validate(loss: ClassCellsLoss, frames: TensorDict, batch_size: int) -> dict[str, float]:
    loss.eval()
    sums: dict[str, float] = {}
    for start in range(0, frames.shape[0], batch_size):
        batch = frames[start:start + batch_size]
        for k, v in loss(batch).items():
            sums[k] = sums.get(k, 0.0) + float(v) * batch.shape[0]
    loss.train()
    return {f"val/{k}": v / frames.shape[0] for k, v in sums.items()}


def question_batches(dataset: MQADataset, split: str, length: int):
    """(tokens [N, length], class distribution [N, 1 + classes]) of the split's questions: uniform over
    the classes a question names (one for COUNTING / EXISTENCE, two for SPATIAL / LOGIC)."""
    questions = dataset.select(split, None, None)
    tokens = torch.zeros(len(questions), length, dtype=torch.int64)
    target = torch.zeros(len(questions), 1 + len(dataset.classes))
    for i, q in enumerate(questions):
        tokens[i, :len(q.tokens)] = torch.tensor(q.tokens)
        for name in q.classes:
            target[i, 1 + dataset.classes.index(name)] += 1.0 / len(q.classes)
    return tokens, target


def train_question(net, dataset: MQADataset, cfg: DictConfig, logger: RunLogger) -> dict:
    """The question encoder and its class attention: cross-entropy against the asked classes."""
    length = max(len(q.tokens) for q in dataset.questions)            # the env's padding
    tokens, target = question_batches(dataset, cfg.frames.split, length)
    params = [*net.question.parameters(), *net.question_classes.parameters()]
    optim = torch.optim.Adam(params, lr=cfg.question.lr)
    g = torch.Generator().manual_seed(cfg.seed)
    result = {}
    for step in range(1, cfg.question.steps + 1):
        idx = torch.randint(len(tokens), (cfg.question.batch_size,), generator=g)
        logits = net.question_classes(net.question(tokens[idx]))
        loss = -(target[idx] * torch.log_softmax(logits, -1)).sum(-1).mean()
        optim.zero_grad()
        loss.backward()
        optim.step()
        if step % 100 == 0 or step == cfg.question.steps:
            with torch.no_grad():
                pick = net.question_classes(net.question(tokens)).argmax(-1)
                result = {"question/loss": float(loss), "question/accuracy": float((target[torch.arange(len(pick)), pick] > 0).float().mean())}
            logger.log_metrics(result, step=cfg.train.steps + step)
    return result


def pretrain_push_trunk(cfg: DictConfig) -> dict:
    """Pretrain the recognition as ``cfg`` (recipes/conf/part/push_trunk.yaml) says; returns the summary it writes."""
    t = cfg.train
    if t.steps < 0 or t.batch_size <= 0 or t.eval_interval <= 0 or cfg.question.steps < 0:
        raise ValueError("train.steps and question.steps must be ≥ 0, train.batch_size and train.eval_interval positive")
    if not Path(cfg.dataset).exists():
        raise FileNotFoundError(f"dataset {cfg.dataset} does not exist: make it with recipes/make_dataset.py")
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seed_run(cfg.seed, cfg.threads)
    dataset = MQADataset(cfg.dataset)
    if t.steps:
        frames = labelled_frames(cfg, dataset, out)
        val_mask = scene_split(frames, cfg.frames.val_fraction, cfg.seed)
        train_frames, val_frames = frames[~val_mask], frames[val_mask]
        print(f"{len(train_frames)} training frames, {len(val_frames)} validation frames", flush=True)
    else:                                       # the question phase alone (init=...): no images needed
        if not cfg.init:
            raise ValueError("train.steps=0 trains only the question part: give init=<recognition.pt> for the visual part")
        frames = train_frames = val_frames = []

    model_cfg = {**OmegaConf.to_container(cfg.model), "class_map": True}
    net = make_push_qnet(model_cfg, vocab_size=len(dataset.vocab), camera_distance=dataset.camera.distance,
                         num_classes=len(dataset.classes))
    init_meta = {}
    if cfg.init:
        init_meta = {f"init/{k}": v for k, v in load_recognition(net, cfg.init, dataset.classes, freeze=False).items()}
        print(f"starting from {cfg.init}")
    loss = ClassCellsLoss(net)
    params = [*net.rgb_trunk.parameters(), *net.class_head.parameters()]
    optim = torch.optim.Adam(params, lr=t.lr)
    config = OmegaConf.to_container(cfg, resolve=True)
    logger = RunLogger(out, cfg.logger, exp_name="push_recognition", config=config)
    meta = {"dataset_sha256": dataset_fingerprint(dataset.root), "frames": len(frames), "val_frames": len(val_frames),
            **init_meta}
    best = {"step": 0}
    t0 = time.perf_counter()
    window: dict[str, list[float]] = {}
    bar = Progress(t.steps, "pretraining", unit="step", disable=not cfg.logger.progress)
    try:
        for step in range(1, t.steps + 1):
            batch = train_frames[torch.randint(len(train_frames), (t.batch_size,))]
            td = loss(random_dihedral_in(batch, (keys.RGB, keys.CLASS_CELLS)) if t.augment else batch)
            optim.zero_grad()
            td["loss_class_cells"].backward()
            torch.nn.utils.clip_grad_norm_(params, t.max_grad_norm)
            optim.step()
            for k, v in td.items():
                window.setdefault(f"train/{k}", []).append(float(v.detach()))
            bar.update(1)
            if step % t.eval_interval == 0 or step == t.steps:
                metrics = {k: float(np.nanmean(v)) for k, v in window.items()}
                window = {}
                metrics["time/steps_per_s"] = step / (time.perf_counter() - t0)
                target = metrics
                if len(val_frames):
                    metrics.update(validate(loss, val_frames, 2 * t.batch_size))
                    target = {k[4:]: v for k, v in metrics.items() if k.startswith("val/")}
                if not len(val_frames) or metrics["val/loss_class_cells"] < best.get("val/loss_class_cells", float("inf")):
                    best = {**{f"val/{k}": v for k, v in target.items()}, "step": step}
                    save_recognition(net, out / RECOGNITION_FILE, dataset.classes, {**meta, **best})
                logger.log_metrics(metrics, step=step)
                bar.set_postfix(acc=f"{target.get('cell_accuracy', float('nan')):.2f}",
                                iou=f"{target.get('target_iou', float('nan')):.2f}")
        visual_seconds = time.perf_counter() - t0
        if (out / RECOGNITION_FILE).exists() and t.steps:   # the best visual weights, then the question phase
            load_recognition(net, out / RECOGNITION_FILE, dataset.classes, freeze=False)
        question = train_question(net, dataset, cfg, logger)
        save_recognition(net, out / RECOGNITION_FILE, dataset.classes, {**meta, **best, **question})
    finally:
        bar.close()
        logger.close()
    summary = {"steps": int(t.steps), "train_frames": len(train_frames), "val_frames": len(val_frames),
               "visual_seconds": round(visual_seconds, 1), "question_seconds": round(time.perf_counter() - t0 - visual_seconds, 1),
               "best": best, "question": question, "file": str(out / RECOGNITION_FILE)}
    write_atomic(out / "summary.json", json.dumps(summary, indent=1))
    print("done:", summary)
    return summary
