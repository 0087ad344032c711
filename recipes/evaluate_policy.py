"""Evaluate a trained push policy greedily against the random baseline on the test split.

    python recipes/evaluate_policy.py run=outputs/train_dqn/local/2026-11-22_09-00-00
    python recipes/evaluate_policy.py run=... policies=[greedy] episodes_per_level=3 video_episodes=3
    python recipes/evaluate_policy.py run=... pusher=arm      # the same policy pushing with the Panda arm
    python recipes/evaluate_policy.py run=... 'policies=[greedy,random,image_teacher]'   # + its teacher
    python recipes/evaluate_policy.py system=dqn_countable_budget_kept     # a dqn system of recipes/conf/systems.yaml
    python recipes/evaluate_policy.py run=... split=train stop_margin=0.5   # choose a stop margin on training scenes
    python recipes/evaluate_policy.py run=... stop_critic=runs/stop/x    # stop learnt by recipes/fit_stop.py
    python recipes/evaluate_policy.py run=... snapshots=true dataset=data/mqa_val   # the learning curve, every snapshot

Per level and policy, over the same questions (the env is seeded alike for every policy): mean
episode reward, pushes, fraction of episodes ending in a simple scene, change of the targets' mean
hidden fraction χ from the first to the last image, fraction of targets fully hidden at the end, the net
number of targets made countable (``countable_gain``: made countable − buried, per episode) and whether a
perfect counter reads the COUNTING answer from I_stop (``counter_stop``) or from either frame
(``counter_either``), the pushes that moved no object by 5 mm (``idle_pushes``) — each with a 95 % interval over episodes (``ci95``) and one that resamples whole scenes
(``scene_low`` / ``scene_high``, shown in results.md); and greedy − each other policy (random, no_manipulation, ...)
paired by question. Writes
``results.json``, ``results.md``, the per-episode metrics (``episodes/<policy>_<level>.pt``) and
videos (Q maps beside the frames) to ``out_dir``, each policy and level as soon as it finishes: run again
with the same ``out_dir``, an evaluation resumes, keeping the finished units that were run on the same questions
(greedy's also with the same weights, stop and kept frame). ``baseline_from=<an earlier out_dir>`` reuses that
evaluation's random episodes when they were run on the same questions (same dataset, split, seed,
episodes, push limit, question types, pusher): the χ metrics carry over, the reward only if the
reward config matches too (else it is left out).

Figures of runs instead of an evaluation (``plot=``, written to ``out_dir``):

    python recipes/evaluate_policy.py 'plot=[runs/global,runs/local,runs/global_local]' out_dir=runs/fig7
    python recipes/evaluate_policy.py 'plot=[runs/curves/global,runs/curves/local]' out_dir=runs/curves

A train_dqn.py run gives a panel of the paper's Fig. 7 (``fig7_rewards.png``): the training reward per episode (the mean
over the episodes that ended in each logged batch, smoothed over ``plot_window`` points) and the greedy evaluations'
(``eval/reward``), against collected frames; a run trained from demonstrations also gets ``fig7_rewards_pretraining.png``
(the pre-training's demonstration loss, ``demo_near``, ``demo_stop_agreement`` per update). A ``snapshots=true`` folder
of this recipe (its ``curve.json``) gives a line of ``curves.png``: the learning curves of several runs, per level.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from mqa_rl.collectors.ray_pool import check_backend
from mqa_rl.data.dataset import MQADataset
from mqa_rl.envs.video import write_video
from mqa_rl.evaluation.episode_metrics import mean_ci95, scene_bootstrap_ci95
from mqa_rl.evaluation.learning_curve import plot_learning_curves, read_curve, run_snapshots
from mqa_rl.evaluation.reward_curves import plot_pretraining, plot_reward_curves, read_scalar
from mqa_rl.evaluation.unit_reuse import content_digest, episodes_meta, greedy_identity, reuse_episodes
from mqa_rl.evaluation.policy_units import REFERENCE_KINDS, close_envs, run_units
from mqa_rl.files import write_atomic
from mqa_rl.modules.frozen_policies import reading_env_options
from mqa_rl.modules.systems import system_spec, systems_by_id
from mqa_rl.modules.push.trained_policy import newest_run_checkpoint, read_run_config
from mqa_rl.training.policy_export import has_dashboards
from mqa_rl.training.run_dir import RunLock
from mqa_rl.training.run_logger import RunLogger
from mqa_rl.transforms.push_memory import memory_radius

REPORTED = ("reward", "pushes", "final_simple", "chi_end", "chi_change", "hidden_end", "into_view", "out_of_view",
            "countable_gain", "counter_stop", "counter_either", "idle_pushes", "stopped")
KEPT_REPORTED = ("counter_kept", "countable_gain_kept", "chi_kept", "hidden_kept")     # with kept_frame=


def shown(stat: dict, sep: str = " ± ") -> str:
    """A mean with its 95 % interval by scene where the episodes name their scenes ([low, high]), else its
    half-width over episodes; the mean alone where there is no interval (one episode: n = 1)."""
    if stat.get("scene_low") is not None and stat["scene_low"] == stat["scene_low"]:
        return f"{stat['mean']:+.3f} [{stat['scene_low']:+.3f}, {stat['scene_high']:+.3f}]"
    ci = stat["ci95"]
    return f"{stat['mean']:+.3f}" if ci != ci else f"{stat['mean']:+.3f}{sep}{ci:.3f}"


def statistics(values: torch.Tensor, scenes: torch.Tensor | None) -> dict:
    """Mean, 95 % half-width and n over episodes; with the episodes' scenes also the 95 % interval that
    resamples whole scenes (a pile's questions share its occlusions: they are not independent)."""
    out = dict(zip(("mean", "ci95", "n"), mean_ci95(values)))
    ok = torch.isfinite(values)
    if scenes is not None and ok.sum() > 0:
        _, low, high, n_scenes = scene_bootstrap_ci95(values[ok], scenes[ok])
        out.update(scene_low=low, scene_high=high, scenes=n_scenes)
    return out


GREEDY_OPTIONS = ("run", "checkpoint", "stop_margin", "stop_critic", "kept_frame", "push_memory")


def as_greedy(cfg: DictConfig) -> DictConfig:
    """``cfg`` with ``system=<a dqn system id>`` turned into the greedy policy's options, as the registry defines
    that system (its run, checkpoint, stop, kept frame, push memory); refused beside any of those options."""
    if not cfg.get("system"):
        return cfg
    spec = system_spec(cfg.systems, cfg.system, kinds=("dqn",))
    given = [k for k in GREEDY_OPTIONS if cfg.get(k) is not None]
    if given:
        raise ValueError(f"system={cfg.system} defines the greedy policy's {', '.join(given)}: give system= or those, "
                         f"not both")
    return OmegaConf.merge(cfg, {"system": None, **{k: spec.get(k) for k in GREEDY_OPTIONS}})


def evaluate(cfg: DictConfig) -> dict:
    """Every policy of ``cfg.policies`` on the same questions per level; writes and returns the results. One writer
    per ``out_dir`` (a second evaluation into it is refused at once)."""
    cfg = as_greedy(cfg)
    with RunLock(Path(cfg.out_dir), "evaluate_policy.py"):
        return _evaluate(cfg)


def _evaluate(cfg: DictConfig) -> dict:
    out = Path(cfg.out_dir)
    check_backend(cfg.backend)
    if "greedy" in cfg.policies and not cfg.run:
        raise ValueError("the greedy policy needs run=<a recipes/train_dqn.py output folder>")
    if cfg.stop_margin is not None and cfg.stop_critic is not None:
        raise ValueError("stop_margin and stop_critic are two stopping rules: give one of them")
    if cfg.stop_margin is not None:
        try:
            float(cfg.stop_margin)
        except (TypeError, ValueError):
            raise ValueError(f"stop_margin={cfg.stop_margin!r} must be a number (e.g. 0.5), inf (never stop) or null "
                             f"(plain greedy)") from None
    try:
        references = systems_by_id(cfg.systems, [p for p in cfg.policies if p != "greedy"], REFERENCE_KINDS)
    except ValueError as error:
        raise ValueError(f"policies: {error}; or greedy, the run's policy") from None
    run_cfg = read_run_config(cfg.run) if cfg.run else None
    dataset = cfg.dataset or (run_cfg.dataset if run_cfg else None)
    if dataset is None:
        raise ValueError("give dataset=... (or run=... to use the run's dataset)")
    reward = OmegaConf.to_container(run_cfg.reward) if run_cfg else OmegaConf.to_container(
        OmegaConf.load(Path(__file__).parent / "conf" / "reward" / "global_local.yaml"))
    max_pushes = int(run_cfg.env.max_pushes) if run_cfg else 10
    qtypes = cfg.question_types or (list(run_cfg.env.question_types) if run_cfg else None)
    push_memory = memory_radius(cfg.push_memory, run_cfg.env if run_cfg else None)
    setup = {"dataset": str(dataset), "reward": reward, "split": cfg.split, "qtypes": qtypes, "max_pushes": max_pushes,
             "pusher": cfg.pusher, "push_memory": push_memory, "seed": int(cfg.seed), "episodes": int(cfg.episodes_per_level),
             "threshold": float(reward.get("simple_threshold", 0.2)), "run": str(cfg.run) if cfg.run else None,
             "checkpoint": cfg.checkpoint, "stop_margin": cfg.stop_margin, "stop_critic": cfg.stop_critic,
             "video_episodes": int(cfg.video_episodes), "systems": references,
             "kept_frame": cfg.kept_frame,
             # a stop or a kept frame reading the counting perception: its frames in every observation (every policy's env alike)
             "frames": reading_env_options({"stop_critic": cfg.stop_critic, "kept_frame": cfg.kept_frame},
                                           {"image_size": int(run_cfg.env.get("image_size", 224)) if run_cfg else 224},
                                           MQADataset(dataset) if cfg.kept_frame else None)}
    reported = (*REPORTED, *KEPT_REPORTED) if cfg.kept_frame else REPORTED
    metrics: dict = {}
    units = []
    identity = greedy_identity(cfg) if "greedy" in cfg.policies else None
    kept = content_digest(cfg.kept_frame, "kept_frame")
    metas = {(level, name): episodes_meta(cfg, dataset, level, qtypes, max_pushes, reward, push_memory, kept)
             | ({"policy": identity} if name == "greedy" else {}) for level in cfg.difficulties for name in cfg.policies}
    needs = KEPT_REPORTED if cfg.kept_frame else ()          # a kept-frame evaluation reports them for every policy
    for (level, name), meta in metas.items():
        reused = reuse_episodes(out, name, meta, needs)        # a killed evaluation resumes
        if reused is None and cfg.baseline_from and name != "greedy":
            reused = reuse_episodes(cfg.baseline_from, name, meta, needs)
            if reused is not None:       # kept here too: evaluations taking this one as their baseline find them
                record_unit(out, meta, cfg.video_format, (level, name), (reused, []))
        if reused is not None:
            metrics[level, name] = reused
        else:
            units.append((level, name))
    try:
        if units:
            for unit, result in run_units(setup, units, cfg.backend, cfg.ray.address, int(cfg.workers)):
                metrics[unit] = record_unit(out, metas[unit], cfg.video_format, unit, result)
    finally:
        close_envs()
    results, lines = {}, []
    nan = torch.full((cfg.episodes_per_level,), float("nan"))
    for level in cfg.difficulties:
        per_policy = {name: metrics[level, name] for name in cfg.policies}
        for name, m in per_policy.items():
            results.setdefault(level, {})[name] = {k: statistics(m.get(k, nan), m.get("scene")) for k in reported}
            print(f"{level:>6} {name:>13}: " + ", ".join(f"{k} {shown(results[level][name][k], sep='±')}" for k in reported),
                  flush=True)
        if "greedy" in per_policy:
            for base in (p for p in per_policy if p != "greedy"):     # paired by question: the same episodes' scenes
                diff = {k: statistics(per_policy["greedy"][k] - per_policy[base].get(k, nan), per_policy["greedy"].get("scene"))
                        for k in reported}
                results[level][f"greedy-{base}"] = diff
    for level, rows in results.items():
        lines.append(f"\n### {level}\n\n| policy | " + " | ".join(reported) + " |\n|---|" + "---|" * len(reported))
        for name, row in rows.items():
            lines.append(f"| {name} | " + " | ".join(f"{shown(row[k])} (n={row[k]['n']})" for k in reported) + " |")
    for name, text in (("results.json", json.dumps(results, indent=2)), ("results.md", "\n".join(lines) + "\n"),
                       ("config.yaml", OmegaConf.to_yaml(cfg, resolve=True))):   # what these figures were measured with
        write_atomic(out / name, text)
    if has_dashboards(cfg.run):                                  # a training run's own (an export is read-only)
        frames = Path(cfg.checkpoint or newest_run_checkpoint(cfg.run)).name.rsplit("-", 1)[-1]
        step = int(frames) if frames.isdigit() else 0
        with RunLogger.of_run(cfg.run) as dashboards:           # at the evaluated checkpoint's frames
            dashboards.log_text("policy_eval/results", f"`{out}`\n" + "\n".join(lines), step)
            dashboards.log_metrics({f"policy_eval/{level}/{name}/{k}": row[k]["mean"] for level, rows in results.items()
                                    for name, row in rows.items() for k in reported}, step)
            for video in sorted((out / "videos").glob("*")):
                dashboards.log_video_file(f"policy_eval/{video.stem}", video, step)
    print("\n".join(lines))
    print(f"written to {out}")
    return results


def evaluate_snapshots(cfg: DictConfig) -> list[tuple[int, dict]]:
    """The learning curve: greedy at every snapshot of the run (``<run>/snapshots``, kept by train_dqn.py's
    ``checkpoint.snapshot_interval_frames``) against the other policies on the same questions, each in
    ``<out_dir>/frames-<N>``; the other policies' episodes run once and are reused. Writes ``curve.json`` and
    ``curve.png`` (greedy − each other policy, per level, 95 % by scene) to ``out_dir``."""
    cfg = as_greedy(cfg)
    if not cfg.run or cfg.checkpoint:
        raise ValueError("snapshots=true evaluates every snapshot of run=<a train_dqn.py run>: give run=, leave checkpoint=null")
    snapshots = run_snapshots(cfg.run)
    if not snapshots:
        raise FileNotFoundError(f"{cfg.run} has no snapshots/checkpoint-*: train it with checkpoint.snapshot_interval_frames=<N> "
                                f"(profile=paper_cpu keeps one every 1,000 frames)")
    if cfg.snapshot_frames is not None:                        # a subset of the curve's points
        held = dict(snapshots)
        missing = sorted(set(map(int, cfg.snapshot_frames)) - set(held))
        if missing:
            raise ValueError(f"snapshot_frames={list(cfg.snapshot_frames)}: {cfg.run} has no snapshot at {missing} frames; "
                             f"it has {sorted(held)} (null: every one)")
        snapshots = [(f, held[f]) for f in sorted(set(map(int, cfg.snapshot_frames)))]
    out = Path(cfg.out_dir)
    first = out / f"frames-{snapshots[0][0]:07d}"
    points = []
    for frames, path in snapshots:
        print(f"=== snapshot at {frames} frames: {path}", flush=True)
        at = OmegaConf.merge(cfg, {"checkpoint": str(path), "out_dir": str(out / f"frames-{frames:07d}"),
                                   "baseline_from": str(first) if frames != snapshots[0][0] else cfg.baseline_from})
        points.append((frames, evaluate(at)))
    write_atomic(out / "curve.json", json.dumps({"run": str(cfg.run), "points": [{"frames": f, "results": r} for f, r in points]},
                                                indent=1))
    plot_learning_curves({Path(cfg.run).name: points}, out / "curve.png")
    if has_dashboards(cfg.run):
        with RunLogger.of_run(cfg.run) as dashboards:
            dashboards.log_figure("policy_eval/learning_curve", out / "curve.png", points[-1][0])
    print(f"learning curve: {out / 'curve.json'}, {out / 'curve.png'}")
    return points


def plot(cfg: DictConfig) -> list[Path]:
    """The figures of the folders ``cfg.plot`` into ``cfg.out_dir``: Fig. 7 of the train_dqn.py runs (a panel each; the
    pre-training's figure of those trained from demonstrations), the learning curves of the ``snapshots=true`` folders."""
    folders = [Path(p) for p in cfg.plot]
    curves = [f for f in folders if (f / "curve.json").is_file()]
    runs = [f for f in folders if f not in curves]
    neither = [str(f) for f in runs if not (f / "csv" / "scalars").is_dir()]
    if neither:
        raise FileNotFoundError(f"plot: {', '.join(neither)} is neither a train_dqn.py run (csv/scalars) nor a "
                                f"snapshots=true folder of this recipe (curve.json); make a learning curve with "
                                f"`python recipes/evaluate_policy.py run=<run> snapshots=true out_dir=<folder>`")
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    if curves:
        written.append(plot_learning_curves({f.name: read_curve(f / "curve.json") for f in curves}, out / "curves.png"))
    pretrained = [run for run in runs if len(read_scalar(run, "demo_pretrain/loss_demo")[0])]
    if pretrained:
        written.append(plot_pretraining(pretrained, out / "fig7_rewards_pretraining.png"))
    rl = [run for run in runs if run not in pretrained or len(read_scalar(run, "train/reward")[0])]
    if rl:                  # every run without pre-training is here: plot_reward_curves() names one with no episode
        written.append(plot_reward_curves(rl, out / "fig7_rewards.png", int(cfg.plot_window)))
    for path in written:
        print(path)
    return written


@hydra.main(config_path="conf", config_name="evaluate_policy", version_base="1.3")
def main(cfg: DictConfig) -> None:
    if cfg.plot:
        plot(cfg)
    elif cfg.snapshots:
        evaluate_snapshots(cfg)
    else:
        evaluate(cfg)


def record_unit(out: Path, meta: dict, video_format: str, unit: tuple[str, str], result) -> dict:
    """Write one finished unit's episodes (and videos) at once, so a killed evaluation keeps what finished;
    returns its per-episode metrics."""
    (level, name), (m, videos) = unit, result
    buffer = io.BytesIO()
    torch.save({"meta": meta, "metrics": m}, buffer)
    write_atomic(out / "episodes" / f"{name}_{level}.pt", buffer.getvalue())
    for i, frames in enumerate(videos):
        write_video(frames, out / "videos" / f"{level}_{i}.{video_format}")
    print(f"  {level} {name}: {len(next(iter(m.values())))} episodes", flush=True)
    return m


if __name__ == "__main__":
    main()
