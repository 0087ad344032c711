"""Load a trained push Q-network from a ``recipes/train_dqn.py`` run folder as a greedy policy.

Used by ``recipes/evaluate_policy.py`` and the web demo. The network is rebuilt from the run's
``config.yaml`` (sized from the env's specs) and its weights read from a checkpoint of the run,
after checking the SHA-256 of every file of that checkpoint: a truncated or edited file is refused
with ``CheckpointCorrupt`` instead of being loaded as garbage.
"""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf
from torchrl.checkpoint import Checkpoint, CheckpointRotation

from mqa_rl import keys
from mqa_rl.modules.push.push_policy import make_push_qnet, make_q_actor
from mqa_rl.verified_checkpoint import CheckpointCorrupt, IntegrityAdapter, newest_checkpoint


RUN_KEYS = ("dataset", "env", "model", "reward")      # what every train_dqn.py config.yaml holds


def read_run_config(run: str | Path, needs: tuple[str, ...] = RUN_KEYS):
    """The ``config.yaml`` of a ``recipes/train_dqn.py`` run folder (or an export of one); a clear error when the
    folder has none, or when its config.yaml lacks the sections ``needs`` (another recipe's: an evaluation's, a
    VQA's)."""
    path = Path(run) / "config.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: run= must be a recipes/train_dqn.py output folder")
    cfg = OmegaConf.load(path)
    missing = [k for k in needs if k not in cfg]
    if missing:
        raise ValueError(f"{path} has no {', '.join(missing)}: {run} is another recipe's folder (an evaluation's, a "
                         f"stop fit's, a VQA's), not a recipes/train_dqn.py run; give run= a train_dqn.py out_dir")
    return cfg


def run_checkpoints(run: str | Path) -> list[Path]:
    """The checkpoints of a run folder, oldest first (empty when it has none)."""
    directory = Path(run) / "checkpoints"
    return sorted(p for p in directory.glob("checkpoint-*") if p.is_dir()) if directory.is_dir() else []


def newest_run_checkpoint(run: str | Path) -> Path | None:
    """The newest readable checkpoint of a run folder (None when it has none); ``CheckpointCorrupt``
    when a newer one cannot be read (``newest_checkpoint``)."""
    return newest_checkpoint(CheckpointRotation(Path(run) / "checkpoints", keep_last=1))


def load_greedy(run: str | Path, checkpoint: str | Path | None, env):
    """The trained Q-network of ``run`` (its config.yaml and newest or given checkpoint), greedy.

    ``env`` (a ``SapienBinEnv`` or a ``TransformedEnv`` over one) gives the vocabulary size, camera
    and action spec. Returns ``(actor, run_config, checkpoint_path)``.
    """
    run = Path(run)
    cfg = read_run_config(run, needs=("model",))          # all the network needs
    base = getattr(env, "base_env", env)
    net = make_push_qnet(cfg.model, vocab_size=env.observation_spec[keys.QUESTION].space.n,
                         camera_distance=base.camera.distance, num_classes=len(base.dataset.classes))
    actor = make_q_actor(net, env.action_spec, masked=cfg.action_mask)
    path = Path(checkpoint) if checkpoint else None
    if path is None:
        path = newest_run_checkpoint(run)
        if path is None:
            raise FileNotFoundError(f"no checkpoint in {run / 'checkpoints'}: train first, or give checkpoint=...")
    try:
        IntegrityAdapter.verify(path, component="policy")
        Checkpoint(policy=actor).load(path, components=["policy"], strict="error", map_location="cpu")
    except Exception as error:
        raise CheckpointCorrupt(f"cannot load the policy from {path} ({error}); is it a train_dqn.py checkpoint "
                                f"of this run's config?") from error
    return actor.eval(), cfg, path
