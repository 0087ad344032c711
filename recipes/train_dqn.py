"""Train the push Q-network with DQN (double DQN, prioritized replay) on SapienBinEnv.

    python recipes/train_dqn.py reward=global         # DQN(R_g)
    python recipes/train_dqn.py reward=local          # DQN(R_l)
    python recipes/train_dqn.py reward=global_local   # DQN(R_g+R_l)
    python recipes/train_dqn.py profile=paper         # the paper's network and settings (ResNet-101, replay 4000)
    python recipes/train_dqn.py out_dir=runs/x resume=true   # continue a killed run from its last checkpoint
    python recipes/train_dqn.py profile=dqfd init_from=runs/student/dqn out_dir=runs/y   # a new phase from a checkpoint
    python recipes/train_dqn.py collector=ray collector.num_workers=8 ray.address=auto    # env actors on a Ray cluster

Config groups (recipes/conf/): reward, trunk, collector, buffer, optim, loss, logger, checkpoint, eval,
ray, profile. The loop follows TorchRL's sota DQN recipe: collect → extend replay → update → log →
sync weights; greedy evaluation on the test split and checkpoints every so many frames.
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import copy
import shutil
import time
import warnings
from pathlib import Path

import hydra
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from torchrl.checkpoint import Checkpoint, CheckpointRotation

from mqa_rl import keys
from mqa_rl.collectors.demonstrations import load_demonstrations
from mqa_rl.collectors.factory import check_collector, make_collector, running, share_train_steps
from mqa_rl.collectors.replay import annealed_is_beta, compact_transitions, make_replay_buffer
from mqa_rl.envs.qmap_overlay import qmap_episode_frames, qmap_image
from mqa_rl.envs.video import write_video
from mqa_rl.evaluation.episode_metrics import episode_metrics, summarise
from mqa_rl.evaluation.rollouts import run_episodes
from mqa_rl.files import write_atomic
from mqa_rl.losses.demonstration import DemonstrationLoss
from mqa_rl.losses.dqn import make_dqn_loss
from mqa_rl.losses.target_map import TargetMapLoss
from mqa_rl.modules.push.pretrained_recognition import load_recognition
from mqa_rl.modules.push.push_policy import RETIRED_OPTIONS, make_explorer, make_push_qnet, make_q_actor
from mqa_rl.progress import Progress
from mqa_rl.training.checkpoint import TrainingCheckpoint
from mqa_rl.training.resume_guard import RESUMABLE, flatten, refuse_changed_config
from mqa_rl.training.run_dir import RunLock, positive_ints, refuse_unresumable
from mqa_rl.training.run_logger import RunLogger, trim_scalars
from mqa_rl.training.signals import exit_on_sigterm
from mqa_rl.verified_checkpoint import newest_checkpoint, restore_verified
from mqa_rl.envs.dihedral import DihedralAugment
from mqa_rl.transforms.mqa_env import make_mqa_env
from mqa_rl.training.seeding import seed_run


def check_config(cfg: DictConfig) -> None:
    """Errors that would otherwise surface minutes later, each saying what to change."""
    col, buf, loss = cfg.collector, cfg.buffer, cfg.loss
    positive_ints(cfg, "collector.frames_per_batch", "collector.total_frames", "buffer.size", "buffer.batch_size",
                  "eval.episodes", "eval.interval_frames", "checkpoint.interval_frames", "checkpoint.keep_last")
    positive_ints(cfg, "loss.updates_per_batch", "collector.annealing_frames", minimum=0)
    if cfg.checkpoint.get("snapshot_interval_frames") is not None:
        positive_ints(cfg, "checkpoint.snapshot_interval_frames")
    if col.total_frames % col.frames_per_batch:
        raise ValueError(f"collector.total_frames={col.total_frames} must be a positive multiple of "
                         f"collector.frames_per_batch={col.frames_per_batch}")
    if cfg.loss.get("target_map_weight", 0) > 0 and not cfg.model.get("class_map"):
        raise ValueError(f"loss.target_map_weight={cfg.loss.target_map_weight} needs model.class_map=true "
                         f"(the target map it trains)")
    if buf.size < buf.batch_size:
        raise ValueError(f"buffer.size={buf.size} must be ≥ buffer.batch_size={buf.batch_size}")
    if not 0.0 <= col.eps_end <= col.eps_init <= 1.0:
        raise ValueError(f"need 0 ≤ collector.eps_end ({col.eps_end}) ≤ collector.eps_init ({col.eps_init}) ≤ 1")
    if cfg.eval.interval_frames <= 0 or cfg.checkpoint.interval_frames <= 0:
        raise ValueError("eval.interval_frames and checkpoint.interval_frames must be positive")
    if not Path(cfg.dataset).exists():
        raise FileNotFoundError(f"dataset {cfg.dataset} does not exist: make it with recipes/make_dataset.py "
                                f"or point dataset=... at one")


# settings removed since, at the value that meant "off": a saved run may name them, a new config does not
RETIRED_SETTINGS = {**{f"model.{k}": v for k, v in RETIRED_OPTIONS.items()}, "demos.max_states": None}


def resumable(saved_config: Path, config: dict) -> tuple[str, ...]:
    """The settings a resume may change: ``RESUMABLE``; the demonstrations' settings when neither the saved run
    nor ``config`` learns from demonstrations (unread then: a changed default of theirs changes no experiment);
    and the removed settings the saved run names at their "off" value (they built the same run)."""
    saved = OmegaConf.to_container(OmegaConf.load(saved_config)) if saved_config.exists() else {}
    no_demos = not (saved.get("demos") or {}).get("path") and not (config.get("demos") or {}).get("path")
    old = flatten(saved)
    retired = tuple(k for k, off in RETIRED_SETTINGS.items() if k in old and old[k] == off)
    return RESUMABLE + ("init_from",) + retired + (("demos.",) if no_demos else ())


INIT_HINT = ("init_from takes a recipes/train_dqn.py run folder (its newest checkpoint), one of its "
             "checkpoints/checkpoint-* folders, or an exported policy (recipes/export_policy.py, e.g. checkpoints/dqn_local)")


def initial_checkpoint(init_from) -> tuple[Path, bool]:
    """The checkpoint a new run starts from (``init_from``) and whether it is a whole training checkpoint (weights,
    optimiser, replay, counters: the run continues it as a new phase) or an exported policy (the weights alone)."""
    path = Path(init_from)
    if not path.exists():
        raise FileNotFoundError(f"init_from={path} does not exist; {INIT_HINT}")
    if path.is_dir() and not (path / "manifest.json").is_file():
        newest = newest_checkpoint(CheckpointRotation(path / "checkpoints", keep_last=1))
        if newest is None:
            raise ValueError(f"init_from={path} holds no checkpoint (no manifest.json, no checkpoints/checkpoint-*); "
                             f"{INIT_HINT}")
        path = newest
    try:
        components = set(Checkpoint.manifest(path)["components"])
    except Exception as error:
        raise ValueError(f"init_from={path} is not a readable checkpoint ({type(error).__name__}: "
                         f"{str(error)[:200]}); {INIT_HINT}") from error
    if "policy" not in components:
        raise ValueError(f"init_from={path} holds no push Q-network (components {sorted(components)}); {INIT_HINT}")
    return path, {"loss", "optimizer", "trainer_state"} <= components


DEMO_METRICS = ("loss_demo", "demo_agreement", "demo_near", "demo_stop_agreement")


def pretrain_on_demonstrations(state, updates, demo_batch, demo_loss, aux_loss, optim, params, target_updater, cfg, logger,
                               save):
    """DQfD's pre-training phase: margin (and target-map) updates on the demonstrations alone, then the
    target network takes the pretrained weights. Counted in ``state`` and checkpointed (``save``) every
    ``demos.checkpoint_updates`` and at the end: a killed or lengthened (``resume=true
    demos.pretrain_updates=<more>``) run continues from the last saved update, repeating none."""
    every = int(cfg.demos.get("checkpoint_updates") or 0)
    started = time.perf_counter()
    window = []
    lr = cfg.demos.get("pretrain_lr") or cfg.optim.lr       # a faster rate gets the pushes' softmax off its plateau
    for group in optim.param_groups:
        group["lr"] = lr
    while state["demo_pretrain_updates"] < updates:
        batch = demo_batch()
        td = demo_loss(batch)
        total = td["loss_demo"] + (aux_loss(batch)["loss_target_map"] if aux_loss is not None else 0.0)
        optim.zero_grad()
        total.backward()
        torch.nn.utils.clip_grad_norm_(params, cfg.optim.max_grad_norm)
        optim.step()
        state["demo_pretrain_updates"] += 1
        now = time.perf_counter()
        state["demo_pretrain_seconds"] += now - started
        started = now
        window.append([td[k].item() for k in DEMO_METRICS])
        if state["demo_pretrain_updates"] % 50 == 0 or state["demo_pretrain_updates"] == updates:
            means = dict(zip(DEMO_METRICS, np.mean(window, 0)))
            logger.log_metrics({f"demo_pretrain/{k}": float(v) for k, v in means.items()}, step=state["demo_pretrain_updates"])
            print(f"demonstration pre-training {state['demo_pretrain_updates']}/{updates}: "
                  + ", ".join(f"{k} {v:.3f}" for k, v in means.items()), flush=True)
            window = []
        if every and state["demo_pretrain_updates"] % every == 0 and state["demo_pretrain_updates"] < updates:
            save()
    for group in optim.param_groups:
        group["lr"] = cfg.optim.lr
    with warnings.catch_warnings():             # the target network starts from the pretrained weights
        warnings.simplefilter("ignore")
        target_updater.init_()
    save()


def learner_device(name: str) -> torch.device:
    """The learner's device (``device=cpu|cuda|cuda:1``); the envs and acting stay on the CPU."""
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device={name} but torch sees no CUDA device (torch {torch.__version__}); use device=cpu")
    return device


def evaluate(env, actor, cfg: DictConfig, logger: RunLogger, step: int) -> dict[str, float]:
    """Greedy episodes on the eval split (same questions every time); Q-map image and videos."""
    base = env.base_env
    base.set_seed(cfg.seed + 10_000)

    def media(i, rollout):
        if i == 0:
            rgb = rollout[keys.RGB][0].numpy().transpose(1, 2, 0)
            logger.log_image("eval/qmap", qmap_image(rgb, rollout[keys.ACTION_VALUE][0], rollout[keys.ACTION_MASK][0]), step)
        if i < cfg.eval.video_episodes:
            frames = qmap_episode_frames(rollout, base.camera, base.question.text)
            path = write_video(frames, logger.media / f"eval_{step:07d}_{i}.{cfg.eval.video_format}")
            logger.log_video_file(f"eval/video_{i}", path, step)

    metrics = run_episodes(env, actor, cfg.eval.episodes, max_pushes=cfg.env.max_pushes,
                           simple_threshold=cfg.reward.simple_threshold, on_episode=media)
    means = summarise(metrics)
    means["stop_rate"] = means.pop("stopped")
    return {f"eval/{k}": v for k, v in means.items()}


def train(cfg: DictConfig) -> dict:
    check_config(cfg)
    check_collector(cfg.collector, cfg.ray.address)      # a Ray head that does not answer: before out_dir exists
    out = Path(cfg.out_dir)
    created = not out.exists()                   # a refused init_from removes only a folder this run made
    with RunLock(out, "train_dqn.py"):
        return _train(cfg, out, created)


def _train(cfg: DictConfig, out: Path, created: bool) -> dict:
    # a new run may start from another's checkpoint; a run that has its own continues from that (resume=true)
    fresh = newest_checkpoint(CheckpointRotation(out / "checkpoints", keep_last=1)) is None
    refuse_unresumable(out, not fresh, bool(cfg.resume))
    init = initial_checkpoint(cfg.init_from) if cfg.get("init_from") and fresh else None
    seed_run(cfg.seed, cfg.threads)
    col, buf = cfg.collector, cfg.buffer

    # ---- env (the eval env doubles as the proof env that sizes the network)
    counter = torch.zeros((), dtype=torch.int64).share_memory_()       # β step counter, shared with workers
    env_cfg = OmegaConf.to_container(cfg.env)
    env_kwargs = dict(dataset=str(cfg.dataset), reward=OmegaConf.to_container(cfg.reward), episode_stats=True, **env_cfg)
    eval_env = make_mqa_env(**{**env_kwargs, "split": cfg.eval.split, "difficulties": cfg.eval.difficulties},
                            counter=counter, seed=cfg.seed + 10_000)          # its reward at the training's β
    vocab = eval_env.observation_spec[keys.QUESTION].space.n
    device = learner_device(cfg.device)
    classes = eval_env.base_env.dataset.classes
    net = make_push_qnet(cfg.model, vocab_size=vocab, camera_distance=eval_env.base_env.camera.distance,
                         num_classes=len(classes))
    if cfg.model.get("pretrained"):              # recognition learnt from the segmentation (pretrain.py part=push_trunk)
        meta = load_recognition(net, cfg.model.pretrained, classes, freeze=cfg.model.get("pretrained_frozen", True))
        print(f"recognition from {cfg.model.pretrained}: {meta}")
    net = net.to(device)
    actor = make_q_actor(net, eval_env.action_spec, masked=cfg.action_mask)
    if init is not None:                         # its weights first: a network of another shape is refused here
        restore_verified(Checkpoint(policy=actor), init[0], "init_from must hold a Q-network of the network this "
                         "config builds (the same model.* settings)", components=["policy"])
    explore = make_explorer(actor, eval_env.action_spec, eps_init=col.eps_init, eps_end=col.eps_end,
                            annealing_frames=col.annealing_frames, masked=cfg.action_mask).to(device)
    egreedy = explore[-1]
    # the envs act on the CPU: a learner on a GPU hands a CPU copy of the policy to the collector
    acting = explore if device.type == "cpu" else copy.deepcopy(explore).to("cpu")

    # ---- loss, optimiser, replay
    loss, target_updater = make_dqn_loss(actor, cfg.loss)
    aux_weight = float(cfg.loss.get("target_map_weight", 0.0))
    aux_loss = TargetMapLoss(net, aux_weight) if aux_weight > 0 else None
    demo_cfg = cfg.get("demos") or {}
    demos = load_demonstrations(demo_cfg["path"], cfg.dataset) if demo_cfg.get("path") else None
    if demos is not None:
        print(f"demonstrations: {len(demos)} states from {demo_cfg['path']}")
    demo_loss = (DemonstrationLoss(net, demo_cfg.get("loss", "margin"), demo_cfg["margin"], demo_cfg["weight"],
                                   demo_cfg.get("smooth_cells", 0.0), demo_cfg.get("stop_margin", 0.0),
                                   demo_cfg.get("direction_weight", 0.0))
                 if demos is not None else None)
    demo_augment = DihedralAugment() if buf.get("augment", "none") == "dihedral" else None

    def demo_batch():
        batch = demos[torch.randint(len(demos), (int(demo_cfg["batch_size"]),))].clone()
        return (demo_augment.forward(batch) if demo_augment is not None else batch).to(device)

    params = [p for p in loss.parameters() if p.requires_grad]
    optim = torch.optim.Adam(params, lr=cfg.optim.lr, weight_decay=cfg.optim.weight_decay)
    out.mkdir(parents=True, exist_ok=True)       # the first thing written
    scratch = Path(buf.scratch_dir) if buf.scratch_dir else out / "replay_scratch"
    if scratch.exists():                     # a previous (killed) process's memmap files: not a checkpoint
        shutil.rmtree(scratch)
    rb = make_replay_buffer(buf, scratch)

    # ---- state and checkpoint
    state = {"frames": 0, "updates": 0, "episodes": 0, "demo_pretrain_updates": 0, "demo_pretrain_seconds": 0.0, "next_eval": int(cfg.eval.interval_frames),
             "next_checkpoint": int(cfg.checkpoint.interval_frames), "train_seconds": 0.0}
    ckpt = TrainingCheckpoint(out / "checkpoints", actor=actor, loss=loss, optimizer=optim, replay_buffer=rb,
                              egreedy=egreedy, target_updater=target_updater, beta_counter=counter, state=state,
                              keep_last=cfg.checkpoint.keep_last)
    if ckpt.latest() is not None:                  # resume=true (refuse_unresumable checked it)
        config = OmegaConf.to_container(cfg, resolve=True)
        refuse_changed_config(out / "config.yaml", config, cfg.get("resume_allow_changes", False),
                              resumable(out / "config.yaml", config))
        path = ckpt.load()
        for group in optim.param_groups:                   # resume_allow_changes: the new settings take effect
            group["lr"], group["weight_decay"] = float(cfg.optim.lr), float(cfg.optim.weight_decay)
        state.setdefault("demo_pretrain_updates", 0)       # checkpoints older than the pre-training counters
        state.setdefault("demo_pretrain_seconds", 0.0)
        dropped = (trim_scalars(out / "csv", state["frames"], exclude="demo_pretrain")         # stepped by frames
                   + trim_scalars(out / "csv" / "scalars" / "demo_pretrain", state["demo_pretrain_updates"]))  # by updates
        print(f"resumed from {path} at {state['frames']} frames, {state['updates']} updates, "
              f"{state['demo_pretrain_updates']} demonstration pre-training updates "
              f"({dropped} log rows after it dropped)")
    elif init is not None and init[1]:
        try:
            path = ckpt.load(init[0])
        except Exception as error:               # e.g. another replay size: leave nothing behind
            shutil.rmtree(scratch, ignore_errors=True)
            if created:
                shutil.rmtree(out, ignore_errors=True)
            raise ValueError(f"init_from={init[0]} does not fit this config ({str(error)[:300]})") from error
        state.setdefault("demo_pretrain_updates", 0)
        state.setdefault("demo_pretrain_seconds", 0.0)
        print(f"a new phase from {path}: its weights, optimiser, replay buffer and counters ({state['frames']} frames, "
              f"{state['updates']} updates, {state['demo_pretrain_updates']} demonstration pre-training updates)")
    elif init is not None:
        print(f"a new run from the Q-network of {init[0]}")
    elif cfg.resume:
        print(f"resume=true but no checkpoint in {ckpt.directory}: starting a new run")
    config = OmegaConf.to_container(cfg, resolve=True)
    # what recipes/evaluate_policy.py rebuilds the network from; rewritten by every (resumed) invocation, so it
    # states the settings that made the newest checkpoint (e.g. a lengthened demos.pretrain_updates)
    write_atomic(out / "config.yaml", OmegaConf.to_yaml(OmegaConf.create(config)))
    logger = RunLogger(out, cfg.logger, exp_name=f"dqn_{cfg.reward.name}_{cfg.model.trunk}", config=config)

    if demos is not None and state["demo_pretrain_updates"] < int(demo_cfg["pretrain_updates"]):
        pretrain_on_demonstrations(state, int(demo_cfg["pretrain_updates"]), demo_batch, demo_loss, aux_loss, optim, params,
                                   target_updater, cfg, logger, save=ckpt.save)
    total = int(col.total_frames)
    remaining = total - state["frames"]
    if remaining > 0:
        collector = make_collector(col, acting, {**env_kwargs, "counter": counter}, total_frames=remaining,
                                   seed=cfg.seed + state["frames"], ray_address=cfg.ray.address)
        if cfg.threads:
            torch.set_num_threads(cfg.threads)
        bar = Progress(total, desc=f"dqn_{cfg.reward.name}", unit="frame", initial=state["frames"],
                       disable=not cfg.logger.progress)
        last_reward = "—"                  # no episode has ended yet in this process
        start, t_wait = time.perf_counter(), time.perf_counter()
        frames_at_start = state["frames"]
        snapshot_every = int(cfg.checkpoint.get("snapshot_interval_frames") or 0)
        with running(collector):
            for data in collector:
                t_collect = time.perf_counter() - t_wait
                data = data.reshape(-1)
                n = data.numel()
                rb.extend(compact_transitions(data))
                state["frames"] += n
                counter.fill_(state["frames"])
                share_train_steps(collector, state["frames"])
                egreedy.step(n)
                metrics = {"train/epsilon": float(egreedy.eps), "train/beta": float(data["next", *keys.BETA].mean()),
                           "time/env_steps_per_s": n / max(t_collect, 1e-9)}
                done = data["next", "done"].squeeze(-1)
                if done.any():
                    ep = episode_metrics(data["next"][done], cfg.reward.simple_threshold)
                    state["episodes"] += int(done.sum())
                    metrics.update({f"train/{k}": v for k, v in summarise(ep).items()})
                    metrics["train/stop_rate"] = metrics.pop("train/stopped")

                # ---- updates
                t0 = time.perf_counter()
                if state["frames"] >= col.learning_starts and len(rb) >= buf.batch_size:
                    losses, qs, aux_terms, demo_terms = [], [], [], []
                    for _ in range(cfg.loss.updates_per_batch):
                        sample = rb.sample().to(device)
                        out_td = loss(sample)
                        total_loss = out_td["loss"]
                        if aux_loss is not None:
                            aux_td = aux_loss(sample)
                            total_loss = total_loss + aux_td["loss_target_map"]
                            aux_terms.append((aux_td["loss_target_map"].item(), aux_td["target_map_iou"].item()))
                        if demo_loss is not None:
                            demo_td = demo_loss(demo_batch())
                            total_loss = total_loss + demo_td["loss_demo"]
                            demo_terms.append([demo_td[k].item() for k in DEMO_METRICS])
                        optim.zero_grad()
                        total_loss.backward()
                        torch.nn.utils.clip_grad_norm_(params, cfg.optim.max_grad_norm)
                        optim.step()
                        target_updater.step()
                        rb.update_tensordict_priority(sample.to("cpu"))
                        state["updates"] += 1
                        losses.append(out_td["loss"].item())
                        qs.append(sample[keys.TD_ERROR].mean().item())
                    rb.sampler.beta = annealed_is_beta(buf.beta_init, state["frames"] / total)
                    if losses:
                        metrics.update({"train/loss": float(np.mean(losses)), "train/td_error": float(np.mean(qs)),
                                        "train/mean_q": float(data[keys.CHOSEN_ACTION_VALUE].mean()),
                                        "train/is_beta": rb.sampler.beta,
                                        "time/updates_per_s": len(losses) / max(time.perf_counter() - t0, 1e-9)})
                    if aux_terms:
                        metrics["train/target_map_loss"], metrics["train/target_map_iou"] = map(float, np.mean(aux_terms, 0))
                    if demo_terms:
                        metrics.update({f"train/{k}": float(v) for k, v in zip(DEMO_METRICS, np.mean(demo_terms, 0))})
                if acting is not explore:
                    acting.load_state_dict(explore.state_dict())
                collector.update_policy_weights_()
                state["train_seconds"] += time.perf_counter() - t_wait
                metrics["time/loop_env_steps_per_s"] = (state["frames"] - frames_at_start) / (time.perf_counter() - start)
                metrics["train/updates"] = state["updates"]
                metrics["train/lr"] = optim.param_groups[0]["lr"]
                metrics["train/episodes"] = state["episodes"]

                if state["frames"] >= state["next_eval"] or state["frames"] >= total:
                    metrics.update(evaluate(eval_env, acting[0], cfg, logger, state["frames"]))
                    while state["next_eval"] <= state["frames"]:
                        state["next_eval"] += int(cfg.eval.interval_frames)
                logger.log_metrics(metrics, step=state["frames"])
                if snapshot_every and state["frames"] >= state.setdefault("next_snapshot", snapshot_every):
                    while state["next_snapshot"] <= state["frames"]:
                        state["next_snapshot"] += snapshot_every
                    ckpt.snapshot()
                if state["frames"] >= state["next_checkpoint"] or state["frames"] >= total:
                    while state["next_checkpoint"] <= state["frames"]:
                        state["next_checkpoint"] += int(cfg.checkpoint.interval_frames)
                    ckpt.save()
                bar.update(n)
                if "train/reward" in metrics and metrics["train/reward"] == metrics["train/reward"]:
                    last_reward = f"{metrics['train/reward']:+.2f}"     # the last batch in which episodes ended
                bar.set_postfix(eps=f"{egreedy.eps.item():.2f}", upd=state["updates"], R=last_reward)
                t_wait = time.perf_counter()
        bar.close()
    if state["frames"] >= total:    # finished: the last checkpoint holds the buffer; free its working copy
        shutil.rmtree(scratch, ignore_errors=True)
    logger.close()
    eval_env.close()
    summary = {"frames": state["frames"], "updates": state["updates"], "episodes": state["episodes"],
               "train_seconds": round(state["train_seconds"], 1),
               "demo_pretrain_updates": state["demo_pretrain_updates"],
               "demo_pretrain_seconds": round(state["demo_pretrain_seconds"], 1), "checkpoint": str(ckpt.latest())}
    print("done:", summary)
    return summary


@hydra.main(config_path="conf", config_name="train_dqn", version_base="1.3")
def main(cfg: DictConfig) -> None:
    exit_on_sigterm()
    train(cfg)


if __name__ == "__main__":
    main()
