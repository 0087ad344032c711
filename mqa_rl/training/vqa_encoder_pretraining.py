"""The VQA's image encoder (EQA's CNN) pretrained on our renders, as EQA did on its own (``recipes/pretrain.py
part=vqa_encoder``): reconstruct the image, label every pixel with its object class (the simulator's segmentation)
and predict its height above the bin floor (depth), all from the CNN's 32×10×10 bottleneck.

Writes ``out_dir/encoder.pt`` (the encoder with the lowest validation loss on held-out scenes; what
recipes/train_vqa.py loads), ``checkpoints/`` (atomic, for resume=true), the logger group's logs
(losses, class accuracy on object pixels, height error), ``config.yaml``, ``summary.json``; or, with
``export_pack=<file>``, only the frames it would train on, in one file (``mqa_rl.training.frame_pack``).
"""


from __future__ import annotations

import json
import random
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict
from torch import nn

from mqa_rl import keys
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.files import write_atomic
from mqa_rl.losses.encoder_pretraining import EncoderPretrainLoss
from mqa_rl.modules.answering.vqa_encoder import FrameEncoder, PretrainHeads, save_encoder
from mqa_rl.training.frame_pack import load_frame_pack, save_frame_pack
from mqa_rl.training.model_checkpoint import ModelCheckpoint
from mqa_rl.training.run_logger import RunLogger, trim_scalars
from mqa_rl.training.vqa_data import pretraining_frames, scene_split
from mqa_rl.envs.dihedral import random_dihedral_in
from mqa_rl.progress import Progress
from mqa_rl.training.seeding import seed_run

ENCODER_FILE = "encoder.pt"


@torch.no_grad()
def validate(loss: EncoderPretrainLoss, frames: TensorDict, device, batch_size: int) -> dict[str, float]:
    loss.eval()
    sums: dict[str, float] = {}
    for start in range(0, frames.shape[0], batch_size):
        batch = frames[start:start + batch_size].to(device)
        for k, v in loss(batch).items():
            sums[k] = sums.get(k, 0.0) + float(v) * batch.shape[0]
    loss.train()
    out = {f"val/{k}": v / frames.shape[0] for k, v in sums.items()}
    out["val/loss"] = sum(v for k, v in out.items() if k.startswith("val/loss_"))
    return out


def read_frames(cfg: DictConfig) -> tuple[TensorDict, dict]:
    """The frames, and what the recipe needs of their dataset (classes, camera distance, fingerprint,
    stores): from the rollout stores and the dataset, or from a frame pack (``frames.pack``) alone."""
    if cfg.frames.pack:
        frames, meta = load_frame_pack(cfg.frames.pack)
        if cfg.frames.max_frames is not None and len(frames) > cfg.frames.max_frames:
            keep = np.random.default_rng(cfg.seed).choice(len(frames), size=cfg.frames.max_frames, replace=False)
            frames = frames[torch.from_numpy(np.sort(keep))]
        return frames, meta
    ds = MQADataset(cfg.dataset)
    frames = pretraining_frames(list(cfg.frames.stores), ds, max_frames=cfg.frames.max_frames, seed=cfg.seed)
    return frames, {"classes": list(ds.classes), "camera_distance": float(ds.camera.distance),
                    "dataset_sha256": dataset_fingerprint(ds.root), "stores": list(cfg.frames.stores)}


def export_pack(cfg: DictConfig) -> Path:
    """Write the frames that training would read (stores, max_frames, seed) to ``cfg.export_pack``."""
    t0 = time.perf_counter()
    frames, source = read_frames(cfg)
    path = save_frame_pack(frames, cfg.export_pack, source)
    print(f"{len(frames)} frames -> {path} ({path.stat().st_size / 1e6:.1f} MB, {time.perf_counter() - t0:.0f} s)")
    return path


def pretrain_vqa_encoder(cfg: DictConfig) -> dict:
    """Pretrain the encoder as ``cfg`` (recipes/conf/part/vqa_encoder.yaml) says; returns the summary it writes."""
    t = cfg.train
    if t.steps <= 0 or t.batch_size <= 0 or t.eval_interval <= 0 or cfg.checkpoint.interval_steps <= 0:
        raise ValueError("train.steps, train.batch_size, train.eval_interval and checkpoint.interval_steps must be positive")
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seed_run(cfg.seed, cfg.threads)
    device = torch.device(cfg.device)
    t0 = time.perf_counter()
    frames, source = read_frames(cfg)
    val_mask = scene_split(frames, cfg.frames.val_fraction, cfg.seed)
    train_frames, val_frames = frames[~val_mask], frames[val_mask]
    train_frames = train_frames.to(device)       # on a GPU the frames stay there (~0.35 MB each): no copy per step
    print(f"{len(train_frames)} training frames, {len(val_frames)} validation frames "
          f"({time.perf_counter() - t0:.0f} s to read)", flush=True)

    num_classes = 1 + len(source["classes"])
    encoder = FrameEncoder(tuple(cfg.encoder.channels), cfg.encoder.image_size, num_classes=num_classes,
                           head_width=cfg.encoder.head_width)
    heads = PretrainHeads(encoder.out_shape[0], num_classes=num_classes, width=cfg.heads.width)
    loss = EncoderPretrainLoss(encoder, heads, camera_distance=source["camera_distance"],
                               weights=OmegaConf.to_container(t.weights),
                               density_sigma=t.density_sigma).to(device)
    model = nn.ModuleDict({"encoder": encoder, "heads": heads})
    params = list(model.parameters())
    optim = torch.optim.Adam(params, lr=t.lr, weight_decay=t.weight_decay)
    state = {"step": 0, "best_val": float("inf"), "best_step": -1, "train_seconds": 0.0}
    ckpt = ModelCheckpoint(out / "checkpoints", model=model, optimizer=optim, state=state, keep_last=cfg.checkpoint.keep_last)
    if ckpt.latest() is not None:
        if not cfg.resume:
            raise FileExistsError(f"{out} already holds checkpoints ({ckpt.latest().name}): pass resume=true to "
                                  f"continue that run, or choose another out_dir")
        path = ckpt.load()
        dropped = trim_scalars(out / "csv", state["step"])
        print(f"resumed from {path} at step {state['step']} ({dropped} log rows after it dropped)")
    elif cfg.resume:
        print(f"resume=true but no checkpoint in {ckpt.directory}: starting a new run")
    if state["step"] >= t.steps and (out / ENCODER_FILE).exists():
        print(f"{out} has finished its {state['step']} steps already (raise train.steps to train on)")
        return json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else dict(state)
    config = OmegaConf.to_container(cfg, resolve=True)
    if not (out / "config.yaml").exists():
        write_atomic(out / "config.yaml", OmegaConf.to_yaml(OmegaConf.create(config)))
    logger = RunLogger(out, cfg.logger, exp_name="vqa_encoder", config=config)
    meta = {"dataset_sha256": source["dataset_sha256"], "classes": list(source["classes"]), "frames": len(frames),
            "stores": list(source["stores"])}

    bar = Progress(t.steps, "encoder pretraining", unit="step", initial=state["step"], disable=not cfg.logger.progress)
    window: dict[str, list[float]] = {}
    try:
        while state["step"] < t.steps:
            t_step = time.perf_counter()
            batch = train_frames[torch.randint(len(train_frames), (t.batch_size,)).to(device)]
            batch = random_dihedral_in(batch, (keys.RGB, keys.DEPTH, keys.CLASS_MAP, keys.OBJECT_MAP)) if t.augment else batch
            td = loss(batch)
            total = sum(v for k, v in td.items() if k.startswith("loss_"))
            optim.zero_grad()
            total.backward()
            torch.nn.utils.clip_grad_norm_(params, t.max_grad_norm)
            optim.step()
            state["step"] += 1
            state["train_seconds"] += time.perf_counter() - t_step
            for k, v in td.items():
                window.setdefault(f"train/{k}", []).append(float(v.detach()))
            bar.update(1)
            step = state["step"]
            if step % t.eval_interval == 0 or step == t.steps:
                metrics = {k: float(np.mean(v)) for k, v in window.items()}
                window = {}
                metrics["time/steps_per_s"] = step / max(state["train_seconds"], 1e-9)
                if len(val_frames):
                    metrics.update(validate(loss, val_frames, device, 2 * t.batch_size))
                    if metrics["val/loss"] < state["best_val"]:
                        state["best_val"], state["best_step"] = metrics["val/loss"], step
                        save_encoder(encoder, out / ENCODER_FILE, {**meta, "step": step, "val": metrics})
                logger.log_metrics(metrics, step=step)
                bar.set_postfix(cls=f"{metrics.get('val/class_accuracy', float('nan')):.2f}",
                                loss=f"{metrics.get('val/loss', float('nan')):.3f}")
            if step % cfg.checkpoint.interval_steps == 0 or step == t.steps:
                ckpt.save(step)
    finally:
        bar.close()
        logger.close()
    if not len(val_frames):
        save_encoder(encoder, out / ENCODER_FILE, {**meta, "step": t.steps})
    summary = {"steps": int(t.steps), "train_frames": len(train_frames), "val_frames": len(val_frames),
               "best_val_loss": state["best_val"] if len(val_frames) else None, "best_step": state["best_step"],
               "train_seconds": round(state["train_seconds"], 1), "encoder": str(out / ENCODER_FILE)}
    write_atomic(out / "summary.json", json.dumps(summary, indent=1))
    print("done:", summary)
    return summary
