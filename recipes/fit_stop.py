"""Learn when a trained push policy should stop, from its own episodes on the training split.

    python recipes/fit_stop.py run=checkpoints/dqn_geometric_student out_dir=runs/stop/geometric_student
    python recipes/evaluate_policy.py run=checkpoints/dqn_geometric_student stop_critic=runs/stop/geometric_student

The policy pushes greedily without stopping (its best allowed push, ``env.max_pushes`` times) over
``episodes_per_level`` training questions per level; every state's features (``stop_features``) and the
targets' χ are kept (``trajectories/<level>.pt``, written per level: an interrupted run continues with the
missing levels). ``value=chi`` (the default) stops where the targets' mean χ is lowest; ``value=uncountable`` where
the fewest targets are below the perfect counter's line (the share of targets a counter misses: what R_c
rewards). ``perception=<file>`` (e.g. ``checkpoints/vqa_counting/perception.pt``) adds its count of the
asked class to every state's features (``PerceivedCount``; the env renders the answer camera at the perception's
size in every state, ~0.2 s each at 448 px). A ``StopCritic`` is fitted by optimal stopping (``mqa_rl.training.optimal_stopping``) on
the episodes of 80 % of the training scenes and scored on the other 20 % against the fixed rules (stop at
once, after k pushes, never) and the hindsight best; then refitted on all episodes and written as
``stop_critic.pt`` with that report (``report.json``). The test split is never read.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from mqa_rl.data.dataset import MQADataset, dataset_fingerprint
from mqa_rl.files import write_atomic
from mqa_rl.modules.answering.perceived_count import PerceivedCount, reading_env_kwargs, token_channels
from mqa_rl.modules.push.trained_policy import load_greedy, read_run_config
from mqa_rl.modules.stop.learned_stop import policy_fingerprint, policy_net
from mqa_rl.modules.stop.stop_margin import StopMargin
from mqa_rl.training.optimal_stopping import fit_stop_critic, fixed_rules, stopped_chi
from mqa_rl.training.stop_trajectories import cached_trajectories, collect_trajectories, held_out, save_trajectories
from mqa_rl.transforms.mqa_env import make_mqa_env
from mqa_rl.transforms.push_memory import memory_radius

VALUES = ("chi", "uncountable")     # what the stop minimises; both are kept per state


def score(critic, data: dict, rows: torch.Tensor, value: str = "chi") -> dict:
    f, chi, valid = data["features"][rows], data[value][rows], data["valid"][rows]
    with torch.no_grad():
        stop = (critic(f) >= 0) & valid
    return {"episodes": int(rows.sum()), "learned": float(stopped_chi(chi, stop, valid).mean()),
            "learned_pushes": float((~stop & valid).long().cumprod(1).sum(1).float().mean()), **fixed_rules(chi, valid)}


@hydra.main(config_path="conf", config_name="fit_stop", version_base="1.3")
def main(cfg: DictConfig) -> None:
    if not cfg.run or not cfg.out_dir:
        raise ValueError("give run=<a recipes/train_dqn.py run or exported policy folder> and out_dir=<where to write>")
    if cfg.value not in VALUES:
        raise ValueError(f"value={cfg.value!r}: the stop minimises one of {list(VALUES)} (the targets' mean χ, or the "
                         "share of targets a perfect counter misses)")
    if cfg.split == "test":
        raise ValueError("split=test: a stop rule fitted on the test split would be judged on what it was fitted to; "
                         "fit on split=train")
    out, run = Path(cfg.out_dir), Path(cfg.run)
    if (out / "stop_critic.pt").exists() and not cfg.overwrite:
        raise FileExistsError(f"{out / 'stop_critic.pt'} exists: choose another out_dir, or overwrite=true")
    run_cfg = read_run_config(run)
    dataset = str(cfg.dataset or run_cfg.dataset)
    max_pushes = int(run_cfg.env.max_pushes)
    push_memory = memory_radius(cfg.push_memory, run_cfg.env)
    torch.set_num_threads(int(cfg.threads))
    reading = PerceivedCount.from_file(cfg.perception, token_channels(MQADataset(dataset)),
                                          num_classes=len(MQADataset(dataset).classes)) if cfg.perception else None
    frames = reading_env_kwargs(reading, int(run_cfg.env.get("image_size", 224)))
    levels, started = {}, time.time()
    for level in cfg.difficulties:
        env = make_mqa_env(dataset, OmegaConf.to_container(run_cfg.reward), split=cfg.split, difficulties=[level], max_pushes=max_pushes,
                           question_types=list(run_cfg.env.question_types), push_memory=push_memory, **frames)
        try:
            actor, _, checkpoint = load_greedy(run, cfg.checkpoint, env)
            net = policy_net(actor)
            meta = {"run": str(run.resolve()), "checkpoint": Path(checkpoint).name, "policy_fingerprint": policy_fingerprint(net),
                    "dataset": dataset_fingerprint(dataset), "split": cfg.split, "level": level, "seed": int(cfg.seed),
                    "episodes": int(cfg.episodes_per_level), "max_pushes": max_pushes, "push_memory": push_memory,
                    "measures": list(VALUES), **({"perception": reading.sha256} if reading else {})}
            path = out / "trajectories" / f"{level}.pt"
            reused = cached_trajectories(path, meta)
            if reused is not None:
                print(f"{level}: {reused['chi'].shape[0]} episodes reused from {path}", flush=True)
                levels[level] = reused
                continue
            env.base_env.set_seed(int(cfg.seed))
            tick = time.time()
            data = collect_trajectories(env, StopMargin(actor, float("inf")), net, int(cfg.episodes_per_level), max_pushes,
                                        reading)
            save_trajectories(path, meta, data)
            levels[level] = data
            print(f"{level}: {data['chi'].shape[0]} episodes with targets in {time.time() - tick:.0f} s", flush=True)
        finally:
            env.close()
    value = str(cfg.value)
    data = {k: torch.cat([levels[lv][k] for lv in levels]) for k in ("features", *VALUES, "valid")}
    data["scenes"] = [s for lv in levels for s in levels[lv]["scenes"]]
    if data["chi"].shape[0] == 0:
        raise ValueError(f"no episode had a target of its question (counts of 0): raise episodes_per_level "
                         f"(now {cfg.episodes_per_level})")
    level_of = torch.cat([torch.full((levels[lv]["chi"].shape[0],), i) for i, lv in enumerate(levels)])
    fit_options = dict(hidden=int(cfg.critic.hidden), iterations=int(cfg.critic.iterations), steps=int(cfg.critic.steps),
                       lr=float(cfg.critic.lr), weight_decay=float(cfg.critic.weight_decay), seed=int(cfg.seed))
    hold = held_out(data["scenes"], float(cfg.holdout_fraction))
    report = {"collect_and_fit_s": None, "fit_episodes": int((~hold).sum()), "held_out_episodes": int(hold.sum())}
    if hold.any() and (~hold).any():
        part = {k: data[k][~hold] for k in ("features", value, "valid")}
        critic, history = fit_stop_critic(part["features"], part[value], part["valid"], **fit_options)
        report["validation"] = {"history": history}
        for i, level in enumerate(levels):
            report["validation"][level] = {"fit": score(critic, data, ~hold & (level_of == i), value),
                                           "held_out": score(critic, data, hold & (level_of == i), value)}
    critic, history = fit_stop_critic(data["features"], data[value], data["valid"], **fit_options)
    report["value"] = value
    report["final"] = {"history": history, **{lv: score(critic, data, level_of == i, value) for i, lv in enumerate(levels)}}
    report["collect_and_fit_s"] = round(time.time() - started, 1)
    meta = {"policy_fingerprint": policy_fingerprint(net), "run": str(run), "checkpoint": Path(checkpoint).name,
            "split": cfg.split, "episodes": int(data["chi"].shape[0]), "fit": fit_options, "push_memory": push_memory,
            "value": value}
    critic.reading = reading
    critic.save(out / "stop_critic.pt", meta)
    write_atomic(out / "report.json", json.dumps(report, indent=2))
    write_atomic(out / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True))   # with the results it made, not before

    rules = ("after_0", "after_1", "after_3", f"after_{max_pushes}", "hindsight")
    what = "χ of the targets" if value == "chi" else "share of targets below the counter's line"
    print(f"mean final {what} (held-out training scenes where a level has some; lower is better):")
    print(f"{'level':>7} {'learned':>8} {'pushes':>7} " + " ".join(f"{r:>10}" for r in rules))
    for level in levels:
        row = report.get("validation", {}).get(level, {}).get("held_out")
        row = row if row and row["episodes"] else report["final"][level]
        print(f"{level:>7} {row['learned']:8.3f} {row['learned_pushes']:7.2f} " + " ".join(f"{row[r]:10.3f}" for r in rules))
    print(f"stop critic: {out / 'stop_critic.pt'} ({report['collect_and_fit_s']} s)")


if __name__ == "__main__":
    main()
