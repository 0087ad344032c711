"""SapienBinEnv inside TorchRL's Collector, MultiSyncCollector (2 worker processes), SerialEnv and ParallelEnv."""

import functools

import pytest
import torch
import yaml

from mqa_rl import keys
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.transforms import make_reward_transform
from mqa_rl.transforms.functional import exploration_reward, global_occlusion_reward, local_occlusion_reward
from conftest import REPO

CONF = REPO / "recipes" / "conf" / "reward"


def _factory(root):
    return functools.partial(SapienBinEnv, str(root), split=None, max_pushes=2)


def _check(data, frames):
    data = data.reshape(-1)
    assert data.numel() == frames
    for key in (keys.RGB, keys.DEPTH, keys.QUESTION, keys.OVERLAP, keys.FULL_AREA, keys.TARGET_MASK):
        assert key in data.keys(True) and ("next", *((key,) if isinstance(key, str) else key)) in data.keys(True)
    assert data[keys.RGB].dtype == torch.uint8 and data[keys.RGB].float().std() > 0
    assert (data["next", keys.INFO, "object_mask"].sum(-1) >= 20).all()


@pytest.mark.timeout(300)
@pytest.mark.parametrize("workers", [1, 2])
def test_collectors(small_dataset_dir, workers):
    """One worker: TorchRL's Collector in this process; two: MultiSyncCollector with worker processes."""
    from torchrl.collectors import Collector, MultiSyncCollector

    make = _factory(small_dataset_dir)
    if workers == 1:
        coll = Collector(make, None, frames_per_batch=3, total_frames=6, auto_register_policy_transforms=False)
    else:
        coll = MultiSyncCollector([make] * workers, None, frames_per_batch=4, total_frames=8,
                                  auto_register_policy_transforms=False)
    try:
        batches = [d.clone() for d in coll]
    finally:
        coll.shutdown()
    assert len(batches) == 2
    for b in batches:
        _check(b, 3 if workers == 1 else 4)


@pytest.mark.timeout(300)
def test_parallel_env_with_batched_reward_stack(small_dataset_dir, small_dataset):
    """ParallelEnv (batch [2]) keeps every key; the reward stack on top of it applies the formulas per env."""
    from torchrl.envs import ParallelEnv, TransformedEnv

    push_length = SapienBinEnv(small_dataset, split=None).push_length
    cfg = yaml.safe_load((CONF / "global_local.yaml").read_text())
    env = TransformedEnv(ParallelEnv(2, _factory(small_dataset_dir)), make_reward_transform(cfg, push_length=push_length))
    try:
        env.set_seed(0)
        r = env.rollout(3, break_when_any_done=False)
    finally:
        env.close()
    assert r.batch_size == torch.Size([2, 3])
    _check(r, 6)
    nxt = r["next"]
    torch.testing.assert_close(nxt[keys.EXPLORATION].squeeze(-1), exploration_reward(
        r[keys.OBJECT_POS], nxt[keys.OBJECT_POS], r[keys.OBJECT_MASK], push_length))
    torch.testing.assert_close(nxt[keys.GLOBAL_OCCLUSION].squeeze(-1), global_occlusion_reward(
        r[keys.OVERLAP], nxt[keys.OVERLAP], r[keys.TARGET_MASK]))
    torch.testing.assert_close(nxt[keys.LOCAL_OCCLUSION].squeeze(-1), local_occlusion_reward(
        r[keys.OVERLAP], nxt[keys.OVERLAP], r[keys.TARGET_MASK]))


@pytest.mark.timeout(300)
@pytest.mark.parametrize("batched", ["SerialEnv", "ParallelEnv"])
def test_batched_envs_pass_check_env_specs_and_pass_on_reset_question(sparse_dataset, batched):
    """A TorchRL user batches envs first: the specs hold there too (the state key ``reset_question`` is returned
    by the batched reset, not only declared), and a ``reset_question`` per env reaches each env."""
    import torchrl.envs
    from tensordict import TensorDict
    from torchrl.envs.utils import check_env_specs

    make = functools.partial(SapienBinEnv, str(sparse_dataset.root), split=None, max_pushes=2, image_size=112)
    env = getattr(torchrl.envs, batched)(2, make)
    try:
        check_env_specs(env, seed=0)
        td = env.reset(TensorDict({keys.RESET_QUESTION: torch.tensor([[1], [0]])}, [2]))
    finally:
        env.close()
    assert td[keys.QUESTION_INDEX].flatten().tolist() == [1, 0]
    assert td[keys.RESET_QUESTION].flatten().tolist() == [-1, -1]       # auto-resets from here pick at random
