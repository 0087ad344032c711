"""Train the two-frame VQA on one MQA system's training rollouts (the policy is frozen; only the VQA learns).

    python recipes/train_vqa.py system=random                       # the counting perception under the paper's head
    python recipes/train_vqa.py system=random vqa=eqa                # the paper's model (EQA's CNN), frozen encoder
    python recipes/train_vqa.py system=random resume=true           # continue a killed run
    python recipes/train_vqa.py system=random encoder.freeze=false device=cuda   # fine-tune the encoder
    python recipes/train_vqa.py system=random vqa=counting encoder.freeze=false \
        init_from=checkpoints/vqa_counting/random train.lr=1e-4     # fine-tune a frozen head with its perception

Reads ``${root}/rollouts/<questions>/<system>/train`` (recipes/collect.py what=rollouts) and the counting perception
(``perception.weights``) or, with vqa=eqa, the pretrained encoder (recipes/pretrain.py part=vqa_encoder); writes to
``out_dir``: ``vqa.pt`` (the model with the best accuracy on held-out training scenes: what
``mqa_rl.modules.answering.vqa.load_vqa`` and recipes/evaluate.py read), ``checkpoints/`` (atomic, for resume=true), ``csv/`` and ``wandb/`` logs (loss, accuracy,
validation accuracy per level), ``config.yaml`` and ``summary.json``.
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

from mqa_rl import keys
from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.collectors.store import read_meta
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import LEVELS
from mqa_rl.files import write_atomic
from mqa_rl.losses.vqa import VQALoss
from mqa_rl.modules.answering.vqa import CHECKPOINT_NAME, grounding_module, save_vqa, vqa_module
from mqa_rl.modules.systems import system_spec
from mqa_rl.training.model_checkpoint import ModelCheckpoint
from mqa_rl.training.resume_guard import RESUMABLE, refuse_changed_config
from mqa_rl.training.run_dir import RunLock, positive_ints, refuse_unresumable
from mqa_rl.training.run_logger import RunLogger, trim_scalars
from mqa_rl.training.signals import exit_on_sigterm
from mqa_rl.training.vqa_build import build_model, start_from
from mqa_rl.training.vqa_data import (Batches, encode_store, load_answering_records, question_class_labels, scene_split,
                                     encoder_fingerprint)
from mqa_rl.envs.dihedral import DIHEDRAL
from mqa_rl.progress import Progress
from mqa_rl.training.seeding import seed_run

# validation metric that picks the kept checkpoint -> its score (higher is better)
SELECT = {"accuracy": lambda m: m["val/accuracy"], "loss": lambda m: -m["val/loss"]}


def check_config(cfg: DictConfig) -> None:
    system_spec(cfg.systems, cfg.system)             # a known system id (recipes/conf/systems.yaml)
    t = cfg.train
    positive_ints(cfg, "train.steps", "train.batch_size", "train.eval_interval", "checkpoint.interval_steps",
                  "checkpoint.keep_last")
    if not t.grounding_weight >= 0.0:
        raise ValueError(f"train.grounding_weight={t.grounding_weight} must be ≥ 0 (0: the question's classes learnt from answers only)")
    if t.select not in SELECT:
        raise ValueError(f"train.select={t.select!r}: choose one of {sorted(SELECT)} (the validation metric that picks vqa.pt)")
    if t.patience_steps is not None:
        positive_ints(cfg, "train.patience_steps")
    if not 0.0 <= t.val_fraction < 1.0:
        raise ValueError(f"train.val_fraction={t.val_fraction} must lie in [0, 1)")
    if not Path(cfg.dataset).exists():
        raise FileNotFoundError(f"dataset {cfg.dataset} does not exist: make it with recipes/make_dataset.py")


@torch.no_grad()
def validate(loss: VQALoss, batches: Batches, device, batch_size: int) -> dict[str, float]:
    """Loss and accuracy over ``batches`` (all of it, in order), overall and per level."""
    loss.network.eval()
    right, levels, losses = [], [], []
    for batch in batches.all(batch_size):
        batch = batch.to(device)
        td = loss.network(batch.copy())
        logits, target = td.get(keys.ANSWER_LOGITS), batch.get(keys.ANSWER_LABEL)
        losses.append(torch.nn.functional.cross_entropy(logits, target, reduction="sum").item())
        right.append((logits.argmax(-1) == target).cpu())
        levels.append(batch.get(keys.LEVEL).cpu())
    loss.network.train()
    right_t, level_t = torch.cat(right).float(), torch.cat(levels)
    out = {"val/accuracy": right_t.mean().item(), "val/loss": sum(losses) / len(right_t)}
    for i, level in enumerate(LEVELS):
        if (level_t == i).any():
            out[f"val/accuracy_{level}"] = right_t[level_t == i].mean().item()
    return out


def check_training_rollouts(meta: dict, rollouts: str) -> str:
    """The split the rollouts were collected on; a VQA learns on training rollouts only (Table III
    evaluates on the test split, so a VQA that saw it would be scored on what it learnt)."""
    split = meta.get("plan", {}).get("split")
    if split != "train":
        raise ValueError(f"rollouts={rollouts} were collected on the {split!r} split: a VQA trains on the training "
                         f"split's rollouts only (python recipes/collect.py what=rollouts system=... 'splits=[train]')")
    return split


def train(cfg: DictConfig) -> dict:
    check_config(cfg)
    out = Path(cfg.out_dir)
    with RunLock(out, "train_vqa.py"):
        return _train(cfg, out)


def _train(cfg: DictConfig, out: Path) -> dict:
    seed_run(cfg.seed, cfg.threads)
    device = torch.device(cfg.device)
    meta = read_meta(cfg.rollouts)
    split = check_training_rollouts(meta, cfg.rollouts)
    ds = MQADataset(cfg.dataset)
    if meta["dataset"]["manifest_sha256"] != dataset_fingerprint(ds.root):
        raise ValueError(f"the rollouts {cfg.rollouts} were collected on another dataset than {cfg.dataset}")
    model, encoder_meta = build_model(cfg, ds)
    if cfg.init_from:
        encoder_meta.update(start_from(model, cfg.init_from))
    model.to(device)

    frozen = bool(cfg.encoder.freeze)
    grounding = grounding_module(model) if model.grounds_classes and cfg.train.grounding_weight > 0 else None
    loss = VQALoss(vqa_module(model, from_features=frozen), label_smoothing=cfg.train.label_smoothing,
                   grounding=grounding, grounding_weight=cfg.train.grounding_weight)
    params = [p for p in model.parameters() if p.requires_grad]
    optim = torch.optim.Adam(params, lr=cfg.train.lr, weight_decay=cfg.train.weight_decay)
    state = {"step": 0, "best_val": -math.inf, "best_step": -1, "best_accuracy": None, "train_seconds": 0.0,
             "select": cfg.train.select}
    ckpt = ModelCheckpoint(out / "checkpoints", model=model, optimizer=optim, state=state, keep_last=cfg.checkpoint.keep_last)
    config = OmegaConf.to_container(cfg, resolve=True)
    refuse_unresumable(out, ckpt.latest() is not None, bool(cfg.resume))
    if ckpt.latest() is not None:
        refuse_changed_config(out / "config.yaml", config, allow=bool(cfg.resume_allow_changes),
                              # when to stop, not how to train; the registry's other systems and how rollouts are
                              # collected (the store it reads is checked by its system and split)
                              free=(*RESUMABLE, "train.steps", "train.patience_steps", "systems.", "collection.",
                                    "vqa.answer_size"))
        state.pop("select")                            # runs older than train.select kept by accuracy
        path = ckpt.load()
        for group in optim.param_groups:               # a deliberate new phase trains under its own settings
            group["lr"], group["weight_decay"] = float(cfg.train.lr), float(cfg.train.weight_decay)
        started = state.setdefault("select", "accuracy")
        if started != cfg.train.select:
            raise ValueError(f"{out} keeps the checkpoint by val/{started}; resume it with train.select={started} "
                             f"(its best score is in those units), or start a new out_dir")
        dropped = trim_scalars(out / "csv", state["step"])
        print(f"resumed from {path} at step {state['step']} ({dropped} log rows after it dropped)")
    elif cfg.resume:
        print(f"resume=true but no checkpoint in {ckpt.directory}: starting a new run")
    steps = int(cfg.train.steps)
    patience = cfg.train.patience_steps
    stopped = patience is not None and state["best_step"] >= 0 and state["step"] - state["best_step"] >= patience
    if (state["step"] >= steps or stopped) and (out / CHECKPOINT_NAME).exists():
        print(f"{out} has finished its {state['step']} steps already" + (
            f" (no better val/{cfg.train.select} in {patience} steps: train.patience_steps=null to train on)" if stopped
            else " (raise train.steps to train on)"))
        return json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else dict(state)

    # ---- data: cached frozen features, or images for fine-tuning
    t0 = time.perf_counter()
    if frozen:
        transforms = DIHEDRAL if cfg.train.augment and not model.invariant_features else 1
        bar = Progress(int(meta["slots"]) * 2, f"encoding ×{transforms}", unit="frame", disable=not cfg.logger.progress)
        model.eval()
        records = encode_store(cfg.rollouts, lambda x: model.encode_frames(x.to(device)).cpu(), transforms=transforms,
                               size=model.frame_size, progress=bar,
                               cache_key=encoder_fingerprint(model.encoder) if model.invariant_features else None)
        bar.close()
        model.train()
    else:
        records = load_answering_records(cfg.rollouts, images=True, size=model.frame_size)
    feature_seconds = time.perf_counter() - t0
    records.set(keys.QUESTION_CLASSES, question_class_labels(records, ds))
    val_mask = scene_split(records, cfg.train.val_fraction, cfg.seed)
    train_set = Batches(records[~val_mask], cfg.train.batch_size, augment=bool(cfg.train.augment))
    val_set = Batches(records[val_mask], cfg.train.batch_size, augment=False) if val_mask.any() else None
    print(f"{cfg.system}: {len(train_set)} training episodes, {int(val_mask.sum())} validation episodes "
          f"({'frozen encoder, features' if frozen else 'fine-tuned encoder'}: {feature_seconds:.0f} s)", flush=True)

    write_atomic(out / "config.yaml", OmegaConf.to_yaml(OmegaConf.create(config)))
    logger = RunLogger(out, cfg.logger, exp_name=f"vqa_{cfg.vqa.name}_{cfg.system}", config=config)
    vqa_meta = {"system": cfg.system, "questions": cfg.questions.name, "question_types": list(cfg.questions.types),
                "rollouts": str(cfg.rollouts), "rollouts_split": split,
                "dataset_sha256": meta["dataset"]["manifest_sha256"], "policy": meta["policy"],
                "encoder": {"weights": cfg.encoder.weights, "frozen": frozen, **encoder_meta},
                "train_episodes": len(train_set), "val_episodes": int(val_mask.sum())}

    stop = False                                       # no better val/<select> in train.patience_steps
    bar = Progress(steps, "vqa", unit="step", initial=state["step"], disable=not cfg.logger.progress)
    window_loss, window_acc, window_ground, t_start = [], [], [], time.perf_counter()
    try:
        while state["step"] < steps:
            t_step = time.perf_counter()
            batch = train_set.sample().to(device)
            td = loss(batch)
            optim.zero_grad()
            sum(v for k, v in td.items() if k.startswith("loss_")).backward()
            torch.nn.utils.clip_grad_norm_(params, cfg.train.max_grad_norm)
            optim.step()
            state["step"] += 1
            state["train_seconds"] += time.perf_counter() - t_step
            window_loss.append(td["loss_vqa"].item())
            window_acc.append(td["accuracy"].item())
            if grounding is not None:
                window_ground.append(td["grounding_accuracy"].item())
            bar.update(1)
            step = state["step"]
            if step % cfg.train.eval_interval == 0 or step == steps:
                metrics = {"train/loss": float(np.mean(window_loss)), "train/accuracy": float(np.mean(window_acc)),
                           "time/steps_per_s": len(window_loss) / max(time.perf_counter() - t_start, 1e-9),
                           "train/lr": optim.param_groups[0]["lr"]}
                if window_ground:
                    metrics["train/grounding_accuracy"] = float(np.mean(window_ground))
                window_loss, window_acc, window_ground, t_start = [], [], [], time.perf_counter()
                if val_set is not None:
                    metrics.update(validate(loss, val_set, device, 4 * cfg.train.batch_size))
                    score = SELECT[cfg.train.select](metrics)
                    if score > state["best_val"]:
                        state["best_val"], state["best_step"], state["best_accuracy"] = score, step, metrics["val/accuracy"]
                        save_vqa(model, out / CHECKPOINT_NAME, {**vqa_meta, "step": step, "val": metrics})
                    stop = patience is not None and step - state["best_step"] >= patience
                logger.log_metrics(metrics, step=step)
                bar.set_postfix(loss=f"{metrics['train/loss']:.3f}",
                                **({"val": f"{metrics['val/accuracy']:.3f}"} if "val/accuracy" in metrics else {}))
            if step % cfg.checkpoint.interval_steps == 0 or step == steps or stop:
                ckpt.save(step)
            if stop:
                break
    finally:
        bar.close()
        logger.close()
    if val_set is None:
        save_vqa(model, out / CHECKPOINT_NAME, {**vqa_meta, "step": steps})
    summary = {"system": cfg.system, "steps": state["step"], "stopped_early": stop,
               "train_episodes": len(train_set), "val_episodes": int(val_mask.sum()),
               "selected_by": f"val/{cfg.train.select}" if val_set is not None else "last step",
               "best_val_accuracy": state.get("best_accuracy") if val_set is not None else None, "best_step": state["best_step"],
               "feature_seconds": round(feature_seconds, 1), "train_seconds": round(state["train_seconds"], 1),
               "vqa": str(out / CHECKPOINT_NAME)}
    write_atomic(out / "summary.json", json.dumps(summary, indent=1))
    print("done:", summary)
    return summary


@hydra.main(config_path="conf", config_name="train_vqa", version_base="1.3")
def main(cfg: DictConfig) -> None:
    exit_on_sigterm()
    train(cfg)


if __name__ == "__main__":
    main()
