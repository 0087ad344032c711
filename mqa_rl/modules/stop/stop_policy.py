"""``StopPolicy``: the "no manipulation" system, which stops at once so that the VQA answers from the
first image (I_stop = I_start)."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from mqa_rl import keys
from mqa_rl.envs import actions


class StopPolicy(TensorDictModuleBase):
    """"No manipulation": stop at the first step, so the last image is the first."""

    in_keys: list = []
    out_keys = [keys.ACTION]

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        tensordict.set(keys.ACTION, torch.full(tensordict.batch_size, actions.STOP, dtype=torch.int64))
        return tensordict
