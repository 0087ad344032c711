"""Demonstrations for the push Q-network: what the privileged oracle does in each state it meets.

The oracle (``PrivilegedPushPolicy``) reads the simulator: the least visible target, the object
covering it, a push that moves that object straight away. A policy acting from rgb, depth and the
question can learn much of that from the images (the occluder lies on the visible part of the
target, higher in depth), and the demonstrations say it with one labelled action per state rather
than with a few noisy rewards per episode. They feed a large-margin loss beside DQN (DQfD, Hester
et al. 2018; ``mqa_rl.losses.demonstration``). States are stored as the replay stores them.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type
from tqdm import tqdm

from mqa_rl import keys
from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.losses.replay import OBS_KEYS
from mqa_rl.modules.privileged_policy import PrivilegedPushPolicy

DEMO_KEYS = (*OBS_KEYS, keys.TARGET_CELLS, keys.ACTION)
DEMOS_META = "demos.json"            # beside the memmap folder "data": written last (recipes/collect_demonstrations.py)


def collect_demonstrations(env, states: int, *, progress: bool = True, learner=None, learner_share: float = 0.0,
                           seed: int = 0, **oracle_options) -> TensorDict:
    """[states] oracle steps (observation, oracle action) on ``env`` (a ``SapienBinEnv``): episodes from
    reset until the episode ends, every step kept, the stops included.

    With a ``learner`` (a greedy policy module, e.g. ``load_greedy``'s), DAgger (Ross et al. 2011): at
    each step the learner's action is executed with probability ``learner_share`` (else the oracle's),
    and the oracle's action is stored either way — labels on the states the learner itself reaches,
    including "stop now" after the learner's own pushes, which the oracle's episodes never show.
    """
    if states < 1:
        raise ValueError(f"need states ≥ 1, got {states}")
    if not 0.0 <= learner_share <= 1.0 or (learner_share > 0 and learner is None):
        raise ValueError(f"learner_share must lie in [0, 1] and needs a learner, got {learner_share}")
    oracle = PrivilegedPushPolicy(env, **oracle_options)
    rng = torch.Generator().manual_seed(seed)
    out = []
    bar = tqdm(total=states, desc="demonstrations", disable=not progress)
    while len(out) < states:
        td = env.reset()
        while len(out) < states:
            td = oracle(td)
            step = td.select(*DEMO_KEYS).clone()
            for key in (keys.DEPTH, keys.TARGET_CELLS):
                step.set(key, step.get(key).to(torch.float16))
            out.append(step)
            bar.update(1)
            if learner is not None and float(torch.rand((), generator=rng)) < learner_share:
                with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
                    td = learner(td)
                oracle.executed(int(td[keys.ACTION]))
            td = env.step(td)
            if td["next", "done"].item():
                break
            td = td["next"]
    bar.close()
    return torch.stack(out)


def load_demonstrations(path, dataset_root: str | Path | None = None) -> TensorDict:
    """The demonstrations in memory; clear errors for a missing, unfinished or other-dataset folder.
    A list of folders is concatenated (DAgger's aggregated data set)."""
    if not isinstance(path, (str, Path)):                     # a list (or hydra ListConfig) of folders
        parts = [load_demonstrations(p, dataset_root) for p in path]
        if not parts:
            raise ValueError("demos.path is an empty list: give one or more demonstration folders")
        return torch.cat([p.select(*DEMO_KEYS) for p in parts])
    path = Path(path)
    hint = "collect them with `python recipes/collect_demonstrations.py` (or set demos.path=null)"
    if not (path / DEMOS_META).exists():
        raise FileNotFoundError(f"no demonstrations in {path} ({DEMOS_META} missing): {hint}")
    meta = json.loads((path / DEMOS_META).read_text())
    if dataset_root is not None and meta.get("dataset_sha256") != dataset_fingerprint(dataset_root):
        raise ValueError(f"the demonstrations in {path} were collected on another dataset than {dataset_root}: {hint}")
    try:
        demos = TensorDict.load_memmap(path / "data").clone()
    except Exception as error:
        raise ValueError(f"cannot read the demonstrations in {path} ({type(error).__name__}: {error}): {hint}") from error
    missing = [k for k in DEMO_KEYS if k not in demos.keys(True)]
    if missing:
        raise ValueError(f"{path} lacks {missing}: {hint}")
    return demos
