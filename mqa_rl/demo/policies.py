"""The policies a visitor can pick: the paper's random baseline, and every trained Q-network found.

Trained policies are ``recipes/train_dqn.py`` run folders (``config.yaml`` + ``checkpoints/``) in a
configured folder (the folder itself, its subfolders and theirs). Each checkpoint is loaded once,
when the server starts (``load_greedy``: weights checked against their SHA-256), and shared by all
visitors (a greedy Q-network has no per-episode state). What cannot be used — a run without a
checkpoint, a corrupt or foreign checkpoint, a stray weights file — is listed with the reason
instead of stopping the server.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from omegaconf import OmegaConf

from mqa_rl.modules.random_policy import RandomMQAPolicy
from mqa_rl.modules.trained_policy import load_greedy, run_checkpoints

log = logging.getLogger(__name__)
RANDOM = "random (paper's baseline)"
RANDOM_MASKED = "random inside the action mask"
WEIGHT_SUFFIXES = (".pt", ".pth", ".ckpt", ".safetensors", ".bin")
TRAIN_HINT = "train one with `python recipes/train_dqn.py out_dir=<runs folder>/<name>`"


@dataclass
class PolicyEntry:
    name: str
    actor: object | None = None        # a greedy QValueActor; None for the random baselines
    masked: bool = False               # random baseline drawing inside the action mask

    @property
    def is_q_network(self) -> bool:
        return self.actor is not None


class PolicyRegistry:
    """Usable policies by display name, and the unusable candidates with their reasons."""

    def __init__(self, runs_dir: str | Path | None, env, max_pushes: int):
        self.runs_dir = Path(runs_dir) if runs_dir else None
        self.max_pushes = max_pushes
        self.entries: dict[str, PolicyEntry] = {RANDOM: PolicyEntry(RANDOM), RANDOM_MASKED: PolicyEntry(RANDOM_MASKED, masked=True)}
        self.problems: list[tuple[str, str]] = []         # (what, why it cannot be used)
        if self.runs_dir is not None and self.runs_dir.is_dir():
            for run in self._run_folders():
                self._load_run(run, env)
            for stray in self._stray_files():
                self.problems.append((str(stray), "a bare weights file, not a recipes/train_dqn.py run folder "
                                                  "(config.yaml + checkpoints/checkpoint-*/): the demo cannot "
                                                  "rebuild its network"))

    # ------------------------------------------------------------------------------ discovery
    def _run_folders(self) -> list[Path]:
        levels = [self.runs_dir, *sorted(p for p in self.runs_dir.iterdir() if p.is_dir())]
        levels += [q for p in levels[1:] for q in sorted(p.iterdir()) if q.is_dir()]
        return [p for p in levels if (p / "config.yaml").is_file()]

    def _stray_files(self) -> list[Path]:
        found = []
        for folder in [self.runs_dir, *(p for p in self.runs_dir.iterdir() if p.is_dir())]:
            found += [f for f in sorted(folder.iterdir()) if f.is_file() and f.suffix.lower() in WEIGHT_SUFFIXES]
        return found

    def _label(self, run: Path) -> str:
        rel = run.relative_to(self.runs_dir).as_posix() if run != self.runs_dir else run.name
        return rel or str(run)

    def _load_run(self, run: Path, env) -> None:
        label = self._label(run)
        try:
            cfg = OmegaConf.load(run / "config.yaml")
            reward = OmegaConf.select(cfg, "reward.name", default="?")
            size = OmegaConf.select(cfg, "env.image_size", default=None)
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
            self.entries[name] = PolicyEntry(name, actor=actor)

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
        if entry.is_q_network:
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
        return "\n".join(lines)
