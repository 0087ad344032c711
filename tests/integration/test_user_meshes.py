"""A user's own meshes (<class>/<instance>/*.obj) as the object library, with convex decomposition."""

import numpy as np
import trimesh

from mqa_rl.data import generate_dataset
from mqa_rl.sim.assets import load_mesh_folder


def _write_meshes(root):
    shapes = {
        "ring": [trimesh.creation.annulus(0.02, 0.04, 0.02), trimesh.creation.annulus(0.015, 0.035, 0.025)],
        "brick": [trimesh.creation.box([0.06, 0.04, 0.03]), trimesh.creation.box([0.05, 0.05, 0.02])],
    }
    for name, meshes in shapes.items():
        for i, m in enumerate(meshes):
            (root / name / f"inst{i}").mkdir(parents=True)
            m.export(root / name / f"inst{i}" / "model.obj")


def test_user_meshes_become_a_dataset(tmp_path):
    _write_meshes(tmp_path / "meshes")
    assets = load_mesh_folder(tmp_path / "meshes")
    ring = next(a for a in assets if a.class_name == "ring")
    assert len(ring.collision_parts) > 1                               # the hole survives decomposition
    true_volume = trimesh.creation.annulus(0.02, 0.04, 0.02).volume
    assert abs(ring.volume - true_volume) / true_volume < 0.35         # a single hull would be +33 %… +100 %
    ds = generate_dataset(tmp_path / "ds", library=tmp_path / "meshes", num_scenes={"easy": 1},
                          objects_per_scene={"easy": 3})
    assert ds.classes == ("brick", "ring")
    assert ds.phrases["ring"] == ("a ring", "rings")
    assert len(ds.questions) == 2 + 2 + 2 + 2
    s = ds.scenes[0]
    assert len(s.objects) == 3 and np.isfinite(s.poses).all()
    assert ds.question(f"{s.id}/counting/ring").answer == str(sum(o.class_name == "ring" for o in s.objects))
