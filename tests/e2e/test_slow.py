"""Long checks, run with `bash tools/test.sh slow` (and by CI): the full default dataset and a physics stress."""

import hashlib

import numpy as np
import pytest
import torch

from mqa_rl.data import generate_dataset

pytestmark = pytest.mark.slow


@pytest.mark.timeout(1200)
def test_default_dataset_is_byte_reproducible_in_one_process_or_two(tmp_path):
    digests = []
    for name, workers in (("a", 1), ("b", 2)):
        ds = generate_dataset(tmp_path / name, seed=0, workers=workers)
        assert len(ds.scenes) == 100 and len(ds.questions) == 80_000
        digests.append({p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in ds.root.rglob("*") if p.is_file()})
    assert digests[0] == digests[1]


@pytest.mark.timeout(1200)
def test_random_pushes_never_escape(small_dataset):
    from mqa_rl.envs import actions
    from mqa_rl.envs.sapien_bin import SapienBinEnv

    env = SapienBinEnv(small_dataset, split=None, difficulties=["hard"], seed=1)
    rng = np.random.default_rng(1)
    td = env.reset()
    for _ in range(300):
        td["action"] = torch.tensor(int(rng.integers(actions.NUM_PUSHES)))
        out = env.step(td)
        poses = env.world.poses()
        assert np.isfinite(poses).all()
        assert env.world.bin.inside(poses[:, :3], margin=-0.005).all()
        td = env.reset() if out["next", "done"].item() else out["next"].clone()
