"""PushMemory: no push twice in an episode (against a greedy policy repeating a push that changed nothing)."""

import pytest
import torch
from omegaconf import OmegaConf
from torchrl.envs.utils import check_env_specs

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.transforms.mqa_env import make_mqa_env
from mqa_rl.transforms.push_memory import PushMemory, memory_radius
from torch_threads import one_torch_thread  # noqa: F401  (autouse)


def test_a_recipes_push_memory_overrides_the_runs_and_negative_means_none():
    run_env = OmegaConf.create({"push_memory": 2})
    assert memory_radius(None, run_env) == 2                      # the run's
    assert memory_radius(1, run_env) == 1 and memory_radius(0, run_env) == 0
    assert memory_radius(-1, run_env) is None                     # -1: switched off
    assert memory_radius(None, OmegaConf.create({"push_memory": None})) is None
    assert memory_radius(None, OmegaConf.create({})) is None and memory_radius(None, None) is None


def test_neighbourhood_marks_the_push_and_same_direction_starts_around_it():
    memory = PushMemory(radius=1)
    a = torch.tensor([actions.encode(2, 5, 0), actions.STOP])
    hood = memory._neighbourhood(a).view(2, actions.DIRECTIONS, actions.GRID, actions.GRID)
    marked = hood[0].nonzero().tolist()
    assert sorted(marked) == sorted([2, r, c] for r in (4, 5, 6) for c in (0, 1))   # clipped at the edge
    assert not hood[1].any()                                                          # stop marks nothing
    assert PushMemory(radius=0)._neighbourhood(a[:1]).sum() == 1
    with pytest.raises(ValueError, match="radius"):
        PushMemory(radius=-1)


def test_env_mask_drops_pushes_made_this_episode_until_reset(small_dataset):
    env = make_mqa_env(small_dataset, None, split=None, seed=0, max_pushes=4, push_memory=1)
    check_env_specs(env)
    td = env.reset()
    assert not td[keys.PUSHED].any()
    allowed = td[keys.ACTION_MASK][: actions.NUM_PUSHES].nonzero().squeeze(-1)
    push = int(allowed[len(allowed) // 2])
    d, r, c = push // actions.GRID ** 2, (push // actions.GRID) % actions.GRID, push % actions.GRID
    td[keys.ACTION] = torch.tensor(push)
    nxt = env.step(td)["next"]
    mask = nxt[keys.ACTION_MASK]
    assert not mask[push] and mask[actions.STOP]
    for dr, dc in ((1, 0), (0, -1), (1, 1)):
        if 0 <= r + dr < actions.GRID and 0 <= c + dc < actions.GRID:
            assert not mask[actions.encode(d, r + dr, c + dc)]
    other = actions.encode((d + 1) % actions.DIRECTIONS, r, c)
    assert nxt[keys.PUSHED].sum() <= 9 and nxt[keys.PUSHED][push]
    assert not nxt[keys.PUSHED][other]                    # the other directions from the same cell stay allowed
    second = int(nxt[keys.ACTION_MASK][: actions.NUM_PUSHES].nonzero()[0])
    nxt[keys.ACTION] = torch.tensor(second)
    after = env.step(nxt)["next"]
    assert not after[keys.ACTION_MASK][push] and not after[keys.ACTION_MASK][second]   # the episode's memory adds up
    td = env.reset()
    assert not td[keys.PUSHED].any()                     # a new episode forgets
