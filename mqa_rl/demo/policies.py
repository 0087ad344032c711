"""The policies a visitor can pick: the systems of the registry offered by id (``recipes/conf/systems.yaml``: the
paper's random baseline, random inside the action mask, no manipulation), and every trained Q-network found.

Trained policies are ``recipes/train_dqn.py`` run folders (``config.yaml`` + ``checkpoints/``) in a
configured folder (the folder itself, its subfolders and theirs). Each checkpoint is loaded once,
when the server starts (``load_greedy``: weights checked against their SHA-256), and shared by all
visitors (a greedy Q-network has no per-episode state). A ``recipes/fit_stop.py`` folder found there
adds its policy with the learned stop (matched by the weights' fingerprint, wherever the run lies).
Other recipes' folders (a VQA, an encoder) are passed over. What cannot be used — a run without a
checkpoint, a corrupt or foreign checkpoint, a stop critic whose policy is absent, a stray weights
file — is listed with the reason instead of stopping the server.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import torch
from omegaconf import OmegaConf

from mqa_rl import keys
from mqa_rl.modules.push.random_policy import RandomMQAPolicy
from mqa_rl.modules.push.trained_policy import load_greedy, run_checkpoints
from mqa_rl.modules.stop.learned_stop import LearnedStop, StopCritic, policy_fingerprint, policy_net
from mqa_rl.modules.stop.stop_policy import StopPolicy

log = logging.getLogger(__name__)
# the registry's systems the demo plays by id: those that need neither a run (found in the runs folder instead)
# nor the simulator's hidden state
OFFERED_KINDS = ("random", "random_masked", "none")
WEIGHT_SUFFIXES = (".pt", ".pth", ".ckpt", ".safetensors", ".bin")
TRAIN_HINT = "train one with `python recipes/train_dqn.py out_dir=<runs folder>/<name>`"
DQN_RUN_KEYS = {"reward", "env", "model"}       # what a train_dqn.py config.yaml has
STOP_FIT_KEYS = {"critic", "run"}                               # what a fit_stop.py config.yaml has


def is_mqa_model_file(path: Path) -> bool:
    """Whether ``path`` is one of mqa_rl's tagged model files (``save_versioned``, the VQA): its format names it."""
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:                                       # noqa: BLE001 - junk, or not a torch file
        return False
    return isinstance(blob, dict) and str(blob.get("format", "")).startswith("mqa_rl.")


@dataclass
class PolicyEntry:
    name: str
    actor: object | None = None        # a greedy QValueActor (or the stop at once); None for the random baselines
    masked: bool = False               # random baseline drawing inside the action mask
    max_pushes: int | None = None      # the run's env.max_pushes (a learned stop's pushes feature is scaled by it)
    trained: bool = True               # a Q-network found in the runs folder (not a system of the registry)

    @property
    def is_q_network(self) -> bool:
        return self.actor is not None and self.trained


def _observed_frame_size(env) -> int:
    """The finest frame ``env`` puts in every observation (``rgb``, or the answer camera's with answer_observation)."""
    spec = env.observation_spec
    return max(spec[k].shape[-1] for k in (keys.RGB, keys.ANSWER_RGB) if k in spec.keys())


class PolicyRegistry:
    """Usable policies by display name, and the unusable candidates with their reasons."""

    def __init__(self, runs_dir: str | Path | None, env, max_pushes: int, systems: Mapping[str, Mapping] | None = None):
        """``systems``: the registry's systems to offer by id (id -> spec, of the kinds in ``OFFERED_KINDS``)."""
        self.runs_dir = Path(runs_dir) if runs_dir else None
        self.max_pushes = max_pushes
        self.entries: dict[str, PolicyEntry] = {name: self._system(name, spec) for name, spec in (systems or {}).items()}
        self.problems: list[tuple[str, str]] = []         # (what, why it cannot be used)
        self.passed_over: list[tuple[str, str]] = []      # (what, why this demo does not offer it): usable elsewhere
        self._frames = _observed_frame_size(env)
        if self.runs_dir is not None and self.runs_dir.is_dir():
            stops = []
            for folder in self._run_folders():
                kind = self._recipe_of(folder)
                if kind == "train_dqn":
                    self._load_run(folder, env)
                elif kind == "fit_stop":
                    stops.append(folder)
            for folder in stops:
                self._load_stop(folder)
            for stray in self._stray_files():
                self.problems.append((str(stray), "a bare weights file, not a recipes/train_dqn.py run folder "
                                                  "(config.yaml + checkpoints/checkpoint-*/): the demo cannot "
                                                  "rebuild its network"))

    @staticmethod
    def _system(name: str, spec: Mapping) -> PolicyEntry:
        kind = spec.get("kind")
        if kind not in OFFERED_KINDS:
            raise ValueError(f"the demo plays systems of kind {', '.join(OFFERED_KINDS)}; {name!r} is {kind!r} "
                             f"(a dqn system's run is offered from the runs folder: runs=<the folder holding it>)")
        if kind == "none":
            return PolicyEntry(name, actor=StopPolicy(), trained=False)
        return PolicyEntry(name, masked=kind == "random_masked", trained=False)

    # ------------------------------------------------------------------------------ discovery
    def _run_folders(self) -> list[Path]:
        levels = [self.runs_dir, *sorted(p for p in self.runs_dir.iterdir() if p.is_dir())]
        levels += [q for p in levels[1:] for q in sorted(p.iterdir()) if q.is_dir()]
        return [p for p in levels if (p / "config.yaml").is_file()]

    def _stray_files(self) -> list[Path]:
        """Weights files that look like a policy someone hoped to load; a recipe folder's own files (beside its
        config.yaml) and mqa_rl's tagged model files (recognition, stop critic, encoder, VQA) are not."""
        found = []
        for folder in [self.runs_dir, *(p for p in self.runs_dir.iterdir() if p.is_dir())]:
            if (folder / "config.yaml").is_file():
                continue
            found += [f for f in sorted(folder.iterdir())
                      if f.is_file() and f.suffix.lower() in WEIGHT_SUFFIXES and not is_mqa_model_file(f)]
        return found

    def _recipe_of(self, folder: Path) -> str | None:
        """"train_dqn", "fit_stop", or None for another recipe's folder; an unreadable config.yaml is listed."""
        try:
            keys = set(OmegaConf.load(folder / "config.yaml").keys())
        except Exception as error:                          # noqa: BLE001 - any unreadable yaml
            self.problems.append((self._label(folder), f"config.yaml unreadable ({type(error).__name__}: {error})"))
            return None
        if DQN_RUN_KEYS <= keys:
            return "train_dqn"
        if STOP_FIT_KEYS <= keys and (folder / "stop_critic.pt").is_file():
            return "fit_stop"
        return None

    def _load_stop(self, folder: Path) -> None:
        """The policy whose weights ``folder``'s critic was fitted for, stopping as the critic predicts."""
        label = self._label(folder)
        try:
            critic, meta = StopCritic.load(folder)
        except (OSError, ValueError) as error:
            self.problems.append((label, str(error)[:400]))
            return
        if critic.reading is not None and critic.reading.input_size > self._frames:
            self.passed_over.append((label, f"its stop reads the counting perception on a {critic.reading.input_size}-px "
                                            f"frame of every state, which this demo does not render (it would slow every "
                                            f"push): roll it out with recipes/evaluate_policy.py or collect.py what=rollouts"))
            return
        wanted = meta.get("policy_fingerprint")
        found = False
        for entry in [e for e in self.entries.values() if e.is_q_network]:
            try:
                if policy_fingerprint(policy_net(entry.actor)) != wanted:
                    continue
            except ValueError:                              # a network without the geometric maps a critic reads
                continue
            name = f"{entry.name} + learned stop · {label}"
            self.entries[name] = PolicyEntry(name, actor=LearnedStop(entry.actor, critic, entry.max_pushes,
                                                                     fingerprint=wanted), max_pushes=entry.max_pushes)
            found = True
        if not found:
            self.problems.append((label, f"a stop critic fitted for the policy of {meta.get('run', '?')}, which is not "
                                         f"among the loaded runs: put that run in `{self.runs_dir}`"))

    def _label(self, run: Path) -> str:
        rel = run.relative_to(self.runs_dir).as_posix() if run != self.runs_dir else run.name
        return rel or str(run)

    def _load_run(self, run: Path, env) -> None:
        label = self._label(run)
        try:
            cfg = OmegaConf.load(run / "config.yaml")
            reward = OmegaConf.select(cfg, "reward.name", default="?")
            size = OmegaConf.select(cfg, "env.image_size", default=None)
            run_pushes = int(OmegaConf.select(cfg, "env.max_pushes", default=self.max_pushes))
        except Exception as error:                          # noqa: BLE001 - any unreadable yaml
            self.problems.append((label, f"config.yaml unreadable ({type(error).__name__}: {error})"))
            return
        image_size = getattr(env, "base_env", env).camera.height
        if size is not None and int(size) != image_size:
            self.problems.append((label, f"trained on {size} px images; the demo's env renders {image_size} px"))
            return
        checkpoints = run_checkpoints(run)
        others = [p for p in (run / "checkpoints").glob("checkpoint-*") if not p.is_dir()] if (run / "checkpoints").is_dir() else []
        for p in others:
            self.problems.append((f"{label}/{p.name}", "not a checkpoint folder (a file where train_dqn.py writes folders)"))
        if not checkpoints:
            if not others:
                self.problems.append((label, "no checkpoint yet (the run was stopped before its first "
                                             "checkpoint.interval_frames)"))
            return
        for ckpt in checkpoints:
            name = f"DQN({reward}) · {label} · {ckpt.name}"
            try:
                actor, _, _ = load_greedy(run, ckpt, env)
            except Exception as error:                      # noqa: BLE001 - listed, never fatal
                self.problems.append((name, str(error)[:400]))
                log.warning("policy %s unusable: %s", name, error)
                continue
            self.entries[name] = PolicyEntry(name, actor=actor, max_pushes=run_pushes)

    # ------------------------------------------------------------------------------ use
    @property
    def names(self) -> list[str]:
        return list(self.entries)

    @property
    def trained(self) -> list[str]:
        return [n for n, e in self.entries.items() if e.is_q_network]

    def get(self, name: str) -> PolicyEntry:
        if name not in self.entries:
            raise KeyError(f"unknown policy {name!r}; choose among {self.names}")
        return self.entries[name]

    def make(self, name: str, seed: int):
        """The policy module for one episode (a fresh seeded random policy, or the shared actor)."""
        entry = self.get(name)
        if entry.actor is not None:
            return entry.actor
        return RandomMQAPolicy(self.max_pushes, seed=seed, masked=entry.masked)

    def status(self) -> str:
        """Markdown: what was found, and what is missing or unusable and why."""
        lines = []
        if not self.trained:
            where = (f"`{self.runs_dir}` does not exist" if self.runs_dir is not None and not self.runs_dir.is_dir()
                     else f"none found in `{self.runs_dir}`" if self.runs_dir is not None else "no runs folder configured")
            lines.append(f"**No trained policy** ({where}): running with the random baseline; {TRAIN_HINT}.")
        else:
            lines.append(f"Trained policies: {len(self.trained)} from `{self.runs_dir}`.")
        for what, why in self.problems:
            lines.append(f"- unusable `{what}`: {why}")
        for what, why in self.passed_over:
            lines.append(f"- not offered here `{what}`: {why}")
        return "\n".join(lines)
