"""The reward stack applied to a batched env (ParallelEnv, batch [2]) matches the formulas per env."""

import functools

import pytest
import torch
import yaml
from pathlib import Path
from torchrl.envs import ParallelEnv, TransformedEnv

from mqa_rl import keys
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.transforms import make_reward_transform
from mqa_rl.transforms.functional import exploration_reward, global_occlusion_reward, local_occlusion_reward

CONF = Path(__file__).parents[1] / "recipes" / "conf" / "reward"


@pytest.mark.timeout(300)
def test_reward_stack_on_parallel_env(small_dataset_dir, small_dataset):
    make = functools.partial(SapienBinEnv, str(small_dataset_dir), split=None, max_pushes=3)
    push_length = SapienBinEnv(small_dataset, split=None).push_length
    cfg = yaml.safe_load((CONF / "global_local.yaml").read_text())
    env = TransformedEnv(ParallelEnv(2, make), make_reward_transform(cfg, push_length=push_length))
    try:
        env.set_seed(0)
        r = env.rollout(3, break_when_any_done=False)
    finally:
        env.close()
    assert r.batch_size == torch.Size([2, 3])
    nxt = r["next"]
    torch.testing.assert_close(nxt[keys.EXPLORATION].squeeze(-1), exploration_reward(
        r[keys.OBJECT_POS], nxt[keys.OBJECT_POS], r[keys.OBJECT_MASK], push_length))
    torch.testing.assert_close(nxt[keys.GLOBAL_OCCLUSION].squeeze(-1), global_occlusion_reward(
        r[keys.OVERLAP], nxt[keys.OVERLAP], r[keys.TARGET_MASK]))
    torch.testing.assert_close(nxt[keys.LOCAL_OCCLUSION].squeeze(-1), local_occlusion_reward(
        r[keys.OVERLAP], nxt[keys.OVERLAP], r[keys.TARGET_MASK]))
