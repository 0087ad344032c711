"""The manipulation policies whose episodes the VQA answers from, built from a small spec (a config
mapping), frozen: nothing here learns.

    {kind: random}                          the paper's baseline: random pushes, random number of them
    {kind: random_masked}                   the same, pushes only inside the action mask
    {kind: none}                            "no manipulation": stop at once (I_stop = I_start)
    {kind: dqn, run: runs/local}            a train_dqn.py run, greedy (newest checkpoint, or checkpoint=...);
                                            epsilon > 0 makes it ε-greedy (rollouts of a question then differ);
                                            stop_margin: m stops only when Q(stop) >= best push + m (StopMargin);
                                            stop_critic: <recipes/fit_stop.py out_dir> stops as it predicts;
                                            push_memory: r (default the run's env.push_memory; < 0: none) runs it
                                            in an env with PushMemory(r), as it was trained (``make_mqa_env(push_memory=r)``)
    {kind: privileged, lookahead: 1}        the oracle reference (reads the simulator; see push.privileged_policy;
                                            order: visible_first, geometry: visible = the image teacher;
                                            refine_radius, require_gain: the refined and countable teachers)
    any kind, kept_frame: <perception.pt>   I_stop is the frame of the episode where that counting perception reads
                                            the most of the asked class, not the last
                                            (``answering.kept_frame.FrameKeeper``; the rollout collector applies it)

``make_frozen_policy(spec, env)`` returns ``(policy, exploration_type)``: ``policy(td)`` writes
``action``; run it under ``set_exploration_type(exploration_type)``. ``is_deterministic(spec)``:
whether every rollout of a question is the same (the env replays bit-identically), in which case a
collection needs one rollout per question. ``resolve_checkpoint(spec)`` pins a dqn spec to the run's
newest checkpoint. ``reading_env_options(spec, ...)``: the env options that the counting perception's
readers in a spec (its ``stop_critic``, its ``kept_frame``) need. The policies themselves live in their own
modules (``push.trained_policy``, ``push.random_policy``, ``push.privileged_policy``; ``stop.stop_policy``,
``stop.stop_margin``, ``stop.learned_stop``; ``answering.kept_frame``); this file only maps specs to them.
The systems, each a spec under an id, are in one registry (``recipes/conf/systems.yaml``, read through ``systems``).
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from pathlib import Path

from omegaconf import OmegaConf
from torchrl.envs.utils import ExplorationType

from mqa_rl.modules.answering.kept_frame import FrameKeeper
from mqa_rl.modules.push.privileged_policy import PrivilegedPushPolicy
from mqa_rl.modules.push.push_policy import make_explorer
from mqa_rl.modules.push.random_policy import RandomMQAPolicy
from mqa_rl.modules.push.trained_policy import load_greedy, newest_run_checkpoint
from mqa_rl.modules.stop.learned_stop import LearnedStop, stop_env_kwargs
from mqa_rl.modules.stop.stop_margin import StopMargin
from mqa_rl.modules.stop.stop_policy import StopPolicy
from mqa_rl.transforms.push_memory import memory_radius

KINDS = ("random", "random_masked", "none", "dqn", "privileged")
PRIVILEGED_OPTIONS = ("min_visible_px", "min_visible_fraction", "max_tries_per_occluder", "lookahead", "order",
                      "geometry", "refine_radius", "require_gain")


def check_spec(spec: Mapping) -> dict:
    """The spec as a plain dict, checked: a known kind, a run folder with a checkpoint for ``dqn``."""
    spec = dict(spec)
    kind = spec.get("kind")
    if kind not in KINDS:
        raise ValueError(f"policy kind {kind!r}; choose one of {KINDS}")
    if kind == "dqn":
        if not spec.get("run"):
            raise ValueError("a dqn policy needs run=<a recipes/train_dqn.py output folder>")
        if not 0.0 <= float(spec.get("epsilon", 0.0)) <= 1.0:
            raise ValueError(f"dqn epsilon={spec['epsilon']} must lie in [0, 1]")
        if spec.get("stop_margin") is not None and spec.get("stop_critic") is not None:
            raise ValueError("a dqn policy takes stop_margin or stop_critic, not both")
        if spec.get("push_memory") is not None and not isinstance(spec["push_memory"], int):
            raise ValueError(f"dqn push_memory={spec['push_memory']!r} must be an integer radius in grid cells "
                             f"(negative: no memory) or null (the run's env.push_memory)")
    if spec.get("kept_frame") is not None and not isinstance(spec["kept_frame"], str):
        raise ValueError(f"kept_frame={spec['kept_frame']!r} must be the path of a counting perception file "
                         f"(e.g. checkpoints/vqa_counting/perception.pt) or null")
    unknown = set(spec) - {"kind", "run", "checkpoint", "epsilon", "stop_margin", "stop_critic", "push_memory",
                           "kept_frame", *PRIVILEGED_OPTIONS}
    if unknown:
        raise ValueError(f"unknown policy option(s) {sorted(unknown)} for kind {kind!r}")
    return spec


def privileged_options(spec: Mapping) -> dict:
    """Every option of the privileged policy ``spec`` builds: the spec's, else ``PrivilegedPushPolicy``'s default (what
    a demonstration set records of its teacher, so that two teachers compare whatever their specs leave out)."""
    defaults = {k: p.default for k, p in inspect.signature(PrivilegedPushPolicy).parameters.items()
                if k in PRIVILEGED_OPTIONS}
    return {**defaults, **{k: spec[k] for k in PRIVILEGED_OPTIONS if k in spec}}


def resolve_checkpoint(spec: Mapping) -> dict:
    """For ``dqn``: the spec with ``checkpoint`` set to the newest one of the run (so that a collection
    records which weights it used, and a run trained further later is not mixed in) and ``push_memory``
    resolved (the spec's, else the run's ``env.push_memory``: a policy is rolled out with the memory it was
    trained and its stop fitted with; absent when none). FileNotFoundError when the run has none yet."""
    spec = check_spec(spec)
    if spec["kind"] != "dqn":
        return spec
    run = Path(spec["run"])
    if not (run / "config.yaml").exists():
        raise FileNotFoundError(f"{run / 'config.yaml'} not found: train the policy first "
                                f"(python recipes/train_dqn.py out_dir={run} reward=...)")
    radius = memory_radius(spec.pop("push_memory", None), OmegaConf.load(run / "config.yaml").get("env"))
    if radius is not None:
        spec["push_memory"] = radius
    if spec.get("checkpoint"):
        return spec
    latest = newest_run_checkpoint(run)
    if latest is None:
        raise FileNotFoundError(f"no checkpoint in {run / 'checkpoints'}: train the policy first")
    return {**spec, "checkpoint": str(latest)}


def is_deterministic(spec: Mapping) -> bool:
    kind = spec["kind"]
    return kind in ("none", "privileged") or (kind == "dqn" and float(spec.get("epsilon", 0.0)) == 0.0)


def make_frozen_policy(spec: Mapping, env, max_pushes: int):
    """(policy, exploration type) for ``env`` (a ``SapienBinEnv``; the privileged policy reads it)."""
    spec = check_spec(spec)
    kind = spec["kind"]
    if kind in ("random", "random_masked"):
        # no seed: draws from the global torch RNG, which the collector seeds per episode
        return RandomMQAPolicy(max_pushes, masked=kind == "random_masked"), ExplorationType.RANDOM
    if kind == "none":
        return StopPolicy(), ExplorationType.DETERMINISTIC
    if kind == "privileged":
        options = {k: spec[k] for k in PRIVILEGED_OPTIONS if k in spec}
        return PrivilegedPushPolicy(env, **options), ExplorationType.DETERMINISTIC
    actor, run_cfg, _ = load_greedy(Path(spec["run"]), spec.get("checkpoint"), env)
    if spec.get("stop_margin") is not None:
        actor = StopMargin(actor, float(spec["stop_margin"]))
    if spec.get("stop_critic") is not None:
        actor = LearnedStop.from_file(actor, spec["stop_critic"], max_pushes, spec.get("push_memory"))
    eps = float(spec.get("epsilon", 0.0))
    if eps == 0.0:
        return actor, ExplorationType.DETERMINISTIC
    explorer = make_explorer(actor, env.action_spec, eps_init=eps, eps_end=eps, annealing_frames=1,
                             masked=bool(run_cfg.action_mask))
    return explorer, ExplorationType.RANDOM


def reading_env_options(spec: Mapping, env_kwargs: Mapping, dataset) -> dict:
    """The env options (beside ``env_kwargs``: image_size, answer_size if any) that the counting perception's readers in
    ``spec`` need (its ``stop_critic``, its ``kept_frame``): the answer camera at the perception's size in every
    observation. ValueError when the env's answer camera renders another size."""
    image_size = env_kwargs["image_size"]
    keeper = FrameKeeper.from_file(spec["kept_frame"], dataset) if spec.get("kept_frame") else None
    frames = {}
    for who, needs in (("stop", stop_env_kwargs(spec.get("stop_critic"), image_size)),
                       ("kept frame", keeper.env_kwargs(image_size) if keeper else {})):
        size = needs.get("answer_size")
        if size is not None and env_kwargs.get("answer_size", frames.get("answer_size", size)) != size:
            raise ValueError(f"the policy's {who} reads the counting perception on {size}-px frames and the env's "
                             f"answer camera renders {env_kwargs.get('answer_size', frames.get('answer_size'))} px: "
                             f"set collection.env.answer_size={size}")
        frames.update(needs)
    if keeper is not None and env_kwargs.get("answer_size", frames.get("answer_size")) is not None:
        frames["answer_observation"] = True       # the kept state's answer frame, whichever state it is
    return frames
