"""Train the VQA's counting perception on labelled frames of fresh piles (recipes/collect.py what=frames).

    python recipes/collect.py what=frames                                  # the frames (pretraining-only dataset)
    python recipes/train_perception.py                                # ~90 min on 2 CPU cores
    python recipes/train_perception.py resume=true                    # continue a killed run
    python recipes/train_perception.py device=cuda train.batch_size=128 model.widths=[48,64,128,192]
    python recipes/train_perception.py model.image_size=224 train.crop=112 ...    # full resolution at 112-px cost
                                                                      # (frames: collect.py what=frames size=224)

Selects by the counting rule itself, on whole held-out pretraining scenes: the share of (frame, class
in the scene) pairs whose count (vote clusters or density, whichever is better) equals the number of
objects with ≥ 20 visible pixels; at the end it chooses the readout and its counting settings (vote
radius, suppression window, probability floor, mass threshold; the density's rounding point) on
those scenes too and writes them into the file (``calibrate_only=true``: only
that, for a run stopped early). ``baseline=<perception.pt>`` counts another file (the shipped one, or the
``init_from``) on the same held-out frames, calibrated the same way: the figure to beat, in ``summary.json``.
Writes ``out_dir/perception.pt`` (the best; ``mqa_rl.modules.answering.perception.load_perception``),
``checkpoints/`` (atomic, for resume=true), ``csv/`` + ``wandb/`` logs, ``config.yaml``, ``summary.json``.
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)
import json
import math
import time
from pathlib import Path

import hydra
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.frame_records import DEPTH_SCHEMA, load_frames
from mqa_rl.collectors.store import read_meta
from mqa_rl.files import write_atomic
from mqa_rl.losses.perception import PerceptionLoss, random_crop
from mqa_rl.modules.answering.perception import (CountingPerception, check_backbone, init_from_file, input_size,
                                                 load_perception, save_perception)
from mqa_rl.training.count_calibration import calibrate_counting, count_accuracy
from mqa_rl.training.model_checkpoint import ModelCheckpoint
from mqa_rl.training.resume_guard import RESUMABLE, refuse_changed_config
from mqa_rl.training.run_dir import RunLock, positive_ints, refuse_unresumable
from mqa_rl.training.perception_maps import perception_maps
from mqa_rl.training.run_logger import RunLogger, trim_scalars
from mqa_rl.training.signals import exit_on_sigterm
from mqa_rl.training.vqa_data import scene_split
from mqa_rl.envs.dihedral import random_dihedral
from mqa_rl.progress import Progress

PERCEPTION_FILE = "perception.pt"
# what training reads of a frame (a depth perception also its DEPTH: an rgb run leaves it on disk)
FRAME_KEYS = (keys.RGB, keys.OBJECT_MAP, keys.OBJECT_CLASSES, keys.FRAME_VISIBLE, keys.SCENE, keys.LEVEL)
COMMAND = "python recipes/train_perception.py"


def check_config(cfg: DictConfig) -> None:
    t = cfg.train
    positive_ints(cfg, "train.steps", "train.batch_size", "train.eval_interval", "checkpoint.interval_steps")
    if not 0.0 < t.val_fraction < 1.0:
        raise ValueError(f"train.val_fraction={t.val_fraction} must lie in (0, 1): the checkpoint is chosen on held-out scenes")
    if t.lr <= 0 or t.warmup_steps < 0:
        raise ValueError(f"train.lr ({t.lr}) must be > 0 and train.warmup_steps ({t.warmup_steps}) ≥ 0")
    check_backbone(cfg.model.backbone, cfg.model.detail, cfg.model.imagenet, cfg.model.depth)   # before any frame is loaded
    full = input_size(cfg.model.image_size, cfg.model.detail, cfg.model.backbone)
    if t.crop and (cfg.model.detail or cfg.model.backbone != "unet" or t.crop % 16 or not 32 <= t.crop < full):
        raise ValueError(f"train.crop={t.crop}: crops are for the plain U-Net (model.detail=0, model.backbone=unet), a "
                         f"multiple of 16 from 32 up to below the frames' {full} px; 0 trains on whole frames")
    for store in cfg.frames.stores:
        read_meta(store)                     # FileNotFoundError naming the recipe that collects it


def calibrate_file(path: Path, val, device) -> dict:
    """Calibrate the counting settings of the perception file at ``path`` on ``val`` and write them into it."""
    model, meta = load_perception(path)
    model.to(device)
    best, after, tried = calibrate_counting(model, val, device)
    model.counting = dict(best)
    save_perception(model, path, {**meta, "counting_calibration": {"chosen": best, "val": after, "tried": tried}})
    print(f"counting settings chosen on {val.shape[0]} held-out frames: {best} -> val count accuracy "
          f"{after['val/count_accuracy']:.3f} (before: {meta.get('val', {}).get('val/count_accuracy', float('nan')):.3f})")
    return after


def subsample(rows: torch.Tensor, limit: int | None, seed: int) -> torch.Tensor:
    """``rows`` (bool) with at most ``limit`` of its set entries kept, chosen at random with ``seed``."""
    n = int(rows.sum())
    if not limit or n <= limit:
        return rows
    keep = torch.from_numpy(np.random.default_rng(seed).choice(n, limit, replace=False)).sort().values
    out = torch.zeros_like(rows)
    out[rows.nonzero().squeeze(1)[keep]] = True
    return out


def baseline_accuracy(path: str, val, device, size: int, depth: bool) -> dict:
    """The count accuracy of another perception file (``baseline=``) on this run's held-out frames, its counting
    settings chosen there as this run's are at its end: the two figures compare on the same frames (a file's own
    ``val`` was drawn from the stores it was trained on)."""
    model, _ = load_perception(path)
    if model.input_size != size or model.depth != depth:
        raise ValueError(f"baseline={path} reads {model.input_size}-px frames{' with depth' if model.depth else ''}, this "
                         f"run's are {size} px{' with depth' if depth else ''}: name a perception of the same input")
    _, after, _ = calibrate_counting(model.to(device), val, device)
    print(f"baseline {path} on these {val.shape[0]} held-out frames, calibrated: {after['val/count_accuracy']:.3f}", flush=True)
    return after


def train(cfg: DictConfig) -> dict:
    check_config(cfg)
    out = Path(cfg.out_dir)
    with RunLock(out, "train_perception.py"):       # one writer; a killed save's checkpoint stage goes
        return _train(cfg, out)


def _train(cfg: DictConfig, out: Path) -> dict:
    torch.manual_seed(cfg.seed)
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    device = torch.device(cfg.device)
    config = OmegaConf.to_container(cfg, resolve=True)

    if not cfg.frames.stores:
        raise ValueError("frames.stores=[] names no frame store: give the folders recipes/collect.py what=frames wrote, "
                         "e.g. 'frames.stores=[runs/perception/frames]'")
    metas = [read_meta(s) for s in cfg.frames.stores]
    if cfg.model.depth and any(m.get("schema", 1) < DEPTH_SCHEMA for m in metas):
        raise ValueError(f"model.depth=true needs frames with depth images; {list(cfg.frames.stores)} were collected "
                         f"without (an older collect.py what=frames): collect them again into a new out_dir")
    stores = list(cfg.frames.stores)
    index = load_frames(stores, (keys.SCENE, keys.LEVEL))     # the split first, then each side's images once
    sizes = {m["plan"]["size"] for m in metas}
    want = input_size(cfg.model.image_size, cfg.model.detail, cfg.model.backbone)
    if sizes != {want}:
        raise ValueError(f"the frames were rendered at {sorted(sizes)} px, the perception reads {want} px "
                         f"(model.image_size={cfg.model.image_size}, model.detail={cfg.model.detail}, model.backbone={cfg.model.backbone}): "
                         f"collect frames at that size (collect.py what=frames size={want}) or set model.image_size / "
                         f"model.detail / model.backbone")
    val_mask = scene_split(index, cfg.train.val_fraction, cfg.seed)
    if not val_mask.any():
        raise ValueError(f"train.val_fraction={cfg.train.val_fraction} holds out no scene of the "
                         f"{len(index.get(keys.SCENE).unique())} in the frames: raise it or collect frames of more scenes")
    val_rows = subsample(val_mask, cfg.train.max_val_frames, cfg.seed)
    train_rows = subsample(~val_mask, cfg.train.max_frames, cfg.seed)     # the data-size ablation (6k / 20k / 50k)
    select = (*FRAME_KEYS, *((keys.DEPTH,) if cfg.model.depth else ()))
    val = load_frames(stores, select, rows=val_rows)
    train_set = load_frames(stores, select, rows=train_rows)
    n_train = train_set.shape[0]
    num_classes = int(cfg.model.num_classes)
    top = max(int(part.get(keys.OBJECT_CLASSES).max()) for part in (val, train_set))
    if top >= num_classes:
        raise ValueError(f"frames hold class {top} but model.num_classes={num_classes}")
    if device.type == "cuda":           # the frames live on the GPU (~0.2 MB each at 224 px): batches never cross the bus
        train_set = train_set.to(device)
    rgb_all, omap_all, cls_all = train_set.get(keys.RGB), train_set.get(keys.OBJECT_MAP), train_set.get(keys.OBJECT_CLASSES)
    vis_all = train_set.get(keys.FRAME_VISIBLE)
    depth_all = train_set.get(keys.DEPTH) if cfg.model.depth else None
    print(f"{n_train} training frames, {val.shape[0]} validation frames ({int(val_mask.sum())} held out) "
          f"from {len(cfg.frames.stores)} store(s)", flush=True)

    baseline = baseline_accuracy(cfg.baseline, val, device, want, bool(cfg.model.depth)) if cfg.baseline else None
    if cfg.calibrate_only:                    # a run stopped early: choose its counting settings now
        return {**calibrate_file(out / PERCEPTION_FILE, val, device), **with_baseline(baseline)}

    model = CountingPerception(num_classes, tuple(cfg.model.widths), int(cfg.model.image_size),
                               detail=int(cfg.model.detail), backbone=cfg.model.backbone, depth=bool(cfg.model.depth))
    if cfg.model.imagenet:
        model.load_imagenet()
    model.to(device)
    if cfg.init_from:
        init_from_file(model, cfg.init_from)
    loss = PerceptionLoss(model, vote_weight=cfg.train.vote_weight, density_weight=cfg.train.density_weight)
    optim = torch.optim.AdamW(model.parameters(), lr=cfg.train.lr, weight_decay=cfg.train.weight_decay)
    steps = int(cfg.train.steps)
    warm = int(cfg.train.warmup_steps)
    factor = lambda s: min(1.0, (s + 1) / max(warm, 1)) * 0.5 * (1 + math.cos(math.pi * min(s, steps) / steps))  # noqa: E731
    schedule = torch.optim.lr_scheduler.LambdaLR(optim, factor)
    state = {"step": 0, "best": -math.inf, "best_step": -1, "train_seconds": 0.0}
    ckpt = ModelCheckpoint(out / "checkpoints", model=model, optimizer=optim, state=state, keep_last=cfg.checkpoint.keep_last)
    refuse_unresumable(out, ckpt.latest() is not None, bool(cfg.resume))
    if ckpt.latest() is not None:
        refuse_changed_config(out / "config.yaml", config, allow=bool(cfg.resume_allow_changes),
                              free=(*RESUMABLE, "train.steps", "calibrate_only", "baseline"))   # a longer run stretches the cosine from here
        ckpt.load()
        schedule.last_epoch = state["step"]            # the warm-up and cosine continue from the restored step
        for group, base in zip(optim.param_groups, schedule.base_lrs):
            group["lr"] = base * factor(state["step"])
        print(f"resumed at step {state['step']} ({trim_scalars(out / 'csv', state['step'])} log rows after it dropped)")
    if state["step"] >= steps and (out / PERCEPTION_FILE).exists():
        if "counting_calibration" in load_perception(out / PERCEPTION_FILE)[1] and (out / "summary.json").exists():
            print(f"{out} has finished its {state['step']} steps already (raise train.steps to train on)")
            return json.loads((out / "summary.json").read_text())
        print(f"{out} has finished its {state['step']} steps but not its counting calibration and summary "
              f"(killed while calibrating): finishing them", flush=True)
        return finish(out, state, steps, val, device, n_train, baseline)
    write_atomic(out / "config.yaml", OmegaConf.to_yaml(OmegaConf.create(config)))
    logger = RunLogger(out, cfg.logger, exp_name="perception", config=config)
    shown = val[torch.linspace(0, val.shape[0] - 1, min(4, val.shape[0])).long()]     # the frames whose maps are logged
    meta = {"command": COMMAND, "frames": [{"store": str(s), "dataset_sha256": m["dataset"]["manifest_sha256"],
                                            "plan": m["plan"]} for s, m in zip(cfg.frames.stores, metas)],
            "train_frames": n_train, "val_frames": int(val.shape[0]), "config": config}

    bar = Progress(steps, "perception", unit="step", initial=state["step"], disable=not cfg.logger.progress)
    window: dict[str, list[float]] = {}
    t_window = time.perf_counter()
    try:
        while state["step"] < steps:
            t0 = time.perf_counter()
            idx = torch.randint(n_train, (cfg.train.batch_size,), device=rgb_all.device)
            images = (rgb_all[idx], omap_all[idx]) + ((depth_all[idx],) if depth_all is not None else ())
            if cfg.train.augment:
                images = random_dihedral(*images)
            batch = {keys.OBJECT_CLASSES: cls_all[idx].to(device), keys.FRAME_VISIBLE: vis_all[idx].to(device)}
            if cfg.train.crop:
                images, slot_area = random_crop(int(cfg.train.crop), *images)
                batch[keys.SLOT_AREA] = slot_area.to(device)
            rgb, omap = images[:2]
            depth = images[2].to(device) if depth_all is not None else None
            batch[keys.OBJECT_MAP] = omap.to(device)
            td = loss(TensorDict(batch, batch_size=[len(idx)]), model.inputs(rgb.to(device), depth, crop=bool(cfg.train.crop)))
            optim.zero_grad()
            loss.total(td).backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.train.max_grad_norm)
            optim.step()
            schedule.step()
            state["step"] += 1
            state["train_seconds"] += time.perf_counter() - t0
            for k, v in td.items():
                window.setdefault(k, []).append(float(v.detach()))
            bar.update(1)
            step = state["step"]
            if step % cfg.train.eval_interval == 0 or step == steps:
                metrics = {f"train/{k}": float(np.mean(v)) for k, v in window.items()}
                metrics["time/steps_per_s"] = len(window["loss_class"]) / max(time.perf_counter() - t_window, 1e-9)
                metrics["train/lr"] = optim.param_groups[0]["lr"]
                metrics.update(count_accuracy(model, val, device))
                window, t_window = {}, time.perf_counter()
                score = max(metrics["val/count_accuracy"], metrics["val/density_count_accuracy"])   # either readout
                if score > state["best"]:
                    state["best"], state["best_step"] = score, step
                    save_perception(model, out / PERCEPTION_FILE,
                                    {**meta, "step": step, "val": metrics, "train_seconds": round(state["train_seconds"], 1)})
                logger.log_metrics(metrics, step=step)
                logger.log_image("val/perception_maps", perception_maps(model, shown, device), step=step)
                bar.set_postfix(loss=f"{metrics['train/loss_class']:.3f}", votes=f"{metrics['val/count_accuracy']:.3f}",
                                density=f"{metrics['val/density_count_accuracy']:.3f}")
            if step % cfg.checkpoint.interval_steps == 0 or step == steps:
                ckpt.save(step)
    finally:
        bar.close()
        logger.close()
    return finish(out, state, steps, val, device, n_train, baseline)


def finish(out: Path, state: dict, steps: int, val, device, n_train: int, baseline: dict | None) -> dict:
    """The counting calibration of the best file on the held-out frames, then ``summary.json``: what a resumed run
    that was killed after its last step still owes (the readers need a calibrated file)."""
    calibrated = calibrate_file(out / PERCEPTION_FILE, val, device)
    summary = {"steps": steps, "best_step": state["best_step"], "best_val_count_accuracy": state["best"],
               "calibrated_val_count_accuracy": calibrated["val/count_accuracy"],
               "train_seconds": round(state["train_seconds"], 1), "train_frames": n_train, "val_frames": int(val.shape[0]),
               "perception": str(out / PERCEPTION_FILE), **with_baseline(baseline)}
    write_atomic(out / "summary.json", json.dumps(summary, indent=1))
    print("done:", summary)
    return summary


def with_baseline(baseline: dict | None) -> dict:
    """The summary's baseline entries (none without ``baseline=``)."""
    if baseline is None:
        return {}
    return {"baseline_calibrated_val_count_accuracy": baseline["val/count_accuracy"],
            "baseline_by_level": {k.rsplit("_", 1)[1]: v for k, v in baseline.items() if k.startswith("val/count_accuracy_")}}


@hydra.main(config_path="conf", config_name="train_perception", version_base="1.3")
def main(cfg: DictConfig) -> None:
    exit_on_sigterm()
    train(cfg)


if __name__ == "__main__":
    main()
