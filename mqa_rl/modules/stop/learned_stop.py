"""LearnedStop: a frozen push policy that stops when a critic predicts that pushing on no longer
lowers the targets' hidden fraction χ.

Why: the imitation students' push branch carries to new scenes, their stop branch does not: it learnt
"easy-looking scene -> stop" from a teacher whose pushes are better than theirs (97 % of easy
episodes stop at once), while the same student pushing ten times keeps uncovering
(docs/notebook/policy.md: the stop threshold, then the learned stop). When to stop is an optimal-stopping problem over the policy's *own* pushes:
stopping at step t leaves χ_t, pushing on leaves whatever a later stop gives. ``StopCritic`` predicts
that change of χ from what the policy sees (``stop_features``); it is fitted by
``mqa_rl.training.optimal_stopping`` on the policy's episodes of the training split
(``recipes/fit_stop.py``), never on the test split.

A critic belongs to one policy: its file records the policy's weight fingerprint and a critic fitted
for other weights is refused. A critic fitted with ``recipes/fit_stop.py perception=<file>`` also reads the
counting perception's count of the asked class (``PerceivedCount``, features ``READING`` after ``FEATURES``); its
file records the perception's path and SHA-256 and the question tokens' classes.
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import nn

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.files import load_versioned, save_versioned
from mqa_rl.modules.answering.perceived_count import READING, PerceivedCount, reading_env_kwargs
from mqa_rl.modules.push.push_qnet import PushQNet
from mqa_rl.modules.stop.q_override import best_allowed_push, take_action

CRITIC_FORMAT = "mqa_rl.stop_critic"
CRITIC_VERSION = 1
HINT = "fit one for this policy with `python recipes/fit_stop.py run=<the policy's run> out_dir=...`"
FEATURES = ("stop_advantage", "best_push_q", "pushes_done", "target_mean", "target_max", "target_cells",
            "presence_mean", "height_mean", "height_max", "height_std", "target_height", "target_relief")


def policy_net(policy) -> PushQNet:
    """The ``PushQNet`` inside a greedy actor (or a wrapper of one)."""
    net = next((m for m in policy.modules() if isinstance(m, PushQNet)), None)
    if net is None:
        raise ValueError("a learned stop needs a push Q-network policy (a recipes/train_dqn.py run)")
    if net.class_head is None:
        raise ValueError("a learned stop reads the policy's target map: the run needs model.class_map=true "
                         "(e.g. profile=student)")
    return net


def policy_fingerprint(net: nn.Module) -> str:
    """SHA-256 over the network's weights: which policy a critic was fitted for."""
    digest = hashlib.sha256()
    for name, value in sorted(net.state_dict().items()):
        digest.update(name.encode())
        digest.update(value.detach().cpu().contiguous().numpy().tobytes())
    return digest.hexdigest()


@torch.no_grad()
def stop_features(net: PushQNet, td: TensorDictBase, max_pushes: int) -> torch.Tensor:
    """[*B, len(FEATURES)] from the observation and the policy's action values (after the policy ran).

    The policy's own view of stopping (Q(stop) − best allowed push, best push), the pushes done, and the
    clutter the geometric maps show: how much of the question's targets is visible (target map t), how
    full and how high the pile stands, how high the visible targets sit and how uneven their cells are."""
    batch = td.batch_size
    q = td.get(keys.ACTION_VALUE).reshape(-1, actions.NUM_ACTIONS).to(torch.float32)
    best, _, any_push = best_allowed_push(q)
    best = torch.where(any_push, best, q[:, actions.STOP])          # no allowed push: no advantage over stop
    rgb, depth = td.get(keys.RGB), td.get(keys.DEPTH)
    maps = net.geometry_maps(rgb.reshape(-1, *rgb.shape[-3:]), depth.reshape(-1, *depth.shape[-3:]),
                             td.get(keys.QUESTION).reshape(-1, td.get(keys.QUESTION).shape[-1]))
    t, presence, h_mean, h_max, h_min = maps.unbind(1)
    weight = t / t.sum((-2, -1), keepdim=True).clamp(min=1e-6)
    pushes = td.get(keys.PUSH_COUNT).reshape(-1).to(torch.float32)
    out = torch.stack([
        q[:, actions.STOP] - best, best, pushes / max(int(max_pushes), 1),
        t.mean((-2, -1)), t.amax((-2, -1)), (t > 0.5).float().mean((-2, -1)),
        presence.mean((-2, -1)), h_mean.mean((-2, -1)), h_max.amax((-2, -1)), h_mean.flatten(1).std(-1),
        (weight * h_mean).sum((-2, -1)), (weight * (h_max - h_min)).sum((-2, -1)),
    ], -1)
    return out.reshape(*batch, len(FEATURES))


class StopCritic(nn.Module):
    """Features [*B, F] -> predicted change of the targets' mean χ if the policy pushes on (< 0: it uncovers).

    ``reading``: the ``PerceivedCount`` whose features follow ``FEATURES`` (None: the shipped features alone);
    its file records the reading's perception path and SHA-256 and its tokens' classes (``reading_source``)."""

    def __init__(self, num_features: int = len(FEATURES), hidden: int = 32):
        super().__init__()
        self.hidden = int(hidden)
        self.reading: PerceivedCount | None = None
        self.register_buffer("mean", torch.zeros(num_features))
        self.register_buffer("std", torch.ones(num_features))
        self.mlp = nn.Sequential(nn.Linear(num_features, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh(),
                                 nn.Linear(hidden, 1))

    def standardise_by(self, features: torch.Tensor) -> None:
        flat = features.reshape(-1, features.shape[-1])
        self.mean.copy_(flat.mean(0))
        self.std.copy_(flat.std(0).clamp(min=1e-6))

    @property
    def feature_names(self) -> list[str]:
        return [*FEATURES, *(READING if self.reading is not None else ())]

    @property
    def reading_source(self) -> dict | None:
        """What the file records of ``reading`` to rebuild it: the perception's path and SHA-256, the tokens' classes."""
        if self.reading is None:
            return None
        return {"perception": self.reading.path, "sha256": self.reading.sha256,
                "token_channel": self.reading.token_channel.detach().cpu().clone()}

    def read(self, net: PushQNet, td: TensorDictBase, max_pushes: int) -> torch.Tensor:
        """[*B, F]: ``stop_features``, then the perceived count when this critic reads it."""
        features = stop_features(net, td, max_pushes)
        if self.reading is None:
            return features
        return torch.cat([features, self.reading.read(td).reshape(*features.shape[:-1], len(READING))], -1)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.mlp((features - self.mean) / self.std).squeeze(-1)

    def save(self, path: str | Path, meta: dict) -> Path:
        """Weights, sizes and ``meta`` (the policy fingerprint, how it was fitted), written atomically."""
        state = {k: v.detach().cpu() for k, v in self.state_dict().items() if not k.startswith("reading.")}
        blob = {"features": self.feature_names, "hidden": self.hidden, "state": state, "meta": dict(meta)}
        if self.reading_source is not None:
            blob["reading"] = dict(self.reading_source)
        return save_versioned(path, CRITIC_FORMAT, CRITIC_VERSION, blob)

    @classmethod
    def load(cls, path: str | Path) -> tuple["StopCritic", dict]:
        """(critic, meta); FileNotFoundError / ValueError that say what to do."""
        path = Path(path).expanduser()
        if path.is_dir():
            path = path / "stop_critic.pt"
        blob = load_versioned(path, CRITIC_FORMAT, CRITIC_VERSION, what="stop-critic file", hint=HINT)
        source = blob.get("reading")
        names = [*FEATURES, *(READING if source is not None else ())]
        if list(blob["features"]) != names:
            raise ValueError(f"{path} reads features {blob['features']}, this mqa_rl computes {names}; {HINT}")
        critic = cls(len(names), int(blob["hidden"]))
        try:
            critic.load_state_dict(blob["state"])
        except (RuntimeError, KeyError) as error:
            raise ValueError(f"{path} holds mismatched weights ({error}); {HINT}") from error
        if source is not None:
            critic.reading = PerceivedCount.from_file(source["perception"], source["token_channel"], source["sha256"])
        return critic.eval(), dict(blob.get("meta", {}))


def stop_env_kwargs(path: str | Path | None, image_size: int) -> dict:
    """``reading_env_kwargs`` of the critic at ``path`` (None: no critic, {})."""
    return {} if path is None else reading_env_kwargs(StopCritic.load(path)[0].reading, image_size)


class LearnedStop(TensorDictModuleBase):
    """``policy`` (greedy Q) pushes its best allowed push until ``critic`` predicts that pushing on does not
    lower χ (prediction >= 0), then stops; a scene without an allowed push stops."""

    def __init__(self, policy, critic: StopCritic, max_pushes: int, fingerprint: str | None = None):
        super().__init__()
        self.policy, self.critic, self.max_pushes = policy, critic.eval(), int(max_pushes)
        self.net = policy_net(policy)
        if fingerprint is not None and fingerprint != policy_fingerprint(self.net):
            raise ValueError(f"this stop critic was fitted for another policy's weights; {HINT}")
        self.in_keys = [*getattr(policy, "in_keys", []), keys.PUSH_COUNT]
        self.out_keys = list(getattr(policy, "out_keys", [keys.ACTION]))
        if critic.reading is not None:          # its reading stays in the state (a FrameKeeper of that perception reuses it)
            self.out_keys.append(keys.PERCEIVED_READING)

    @classmethod
    def from_file(cls, policy, path: str | Path, max_pushes: int, push_memory: int | None = None) -> "LearnedStop":
        """``push_memory``: the memory the env runs with; a critic fitted under another one predicts for pushes
        the policy will not make (a warning; files written before the fit recorded it are not checked)."""
        critic, meta = StopCritic.load(path)
        if "push_memory" in meta and meta["push_memory"] != push_memory:
            warnings.warn(f"{path}: this stop critic was fitted with push_memory={meta['push_memory']} and runs with "
                          f"push_memory={push_memory}; refit it with recipes/fit_stop.py push_memory=<the same>", stacklevel=2)
        return cls(policy, critic, max_pushes, fingerprint=meta.get("policy_fingerprint"))

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        tensordict = self.policy(tensordict)
        q = tensordict.get(keys.ACTION_VALUE)
        _, best_push, any_push = best_allowed_push(q)
        with torch.no_grad():
            features = self.critic.read(self.net, tensordict, self.max_pushes)
            gain = self.critic(features)
        if self.critic.reading is not None:
            tensordict.set(keys.PERCEIVED_READING, features[..., -len(READING):])
        action = tensordict.get(keys.ACTION)
        push_on = (any_push & (gain < 0)).reshape(action.shape)
        chosen = torch.where(push_on, best_push.reshape(action.shape), torch.full_like(action, actions.STOP))
        return take_action(tensordict, q, chosen)
