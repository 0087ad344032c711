"""Camera model and full silhouettes (A_t) against SAPIEN's own camera and renderer."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mqa_rl.sim.geometry import CameraSpec, matrix_to_wxyz, wxyz_to_matrix
from mqa_rl.sim.silhouette import convex_polygon_mask, silhouettes


def test_project_unproject_roundtrip():
    cam = CameraSpec()
    pts = np.random.default_rng(0).uniform([-0.2, -0.2, 0], [0.2, 0.2, 0.3], (50, 3))
    uv, z = cam.project(pts)
    np.testing.assert_allclose(cam.unproject(uv, z), pts, atol=1e-12)


def test_image_axes_follow_world_axes():
    cam = CameraSpec()
    (u0, v0), _ = cam.project(np.zeros(3))
    (ux, vx), _ = cam.project(np.array([0.1, 0, 0]))
    (uy, vy), _ = cam.project(np.array([0, 0.1, 0]))
    assert (u0, v0) == (cam.width / 2, cam.height / 2)
    assert ux > u0 and vx == v0          # world +x → image right
    assert vy < v0 and uy == u0          # world +y → image up


def test_quaternion_roundtrip():
    r = Rotation.random(5, random_state=1).as_matrix()
    for m in r:
        np.testing.assert_allclose(wxyz_to_matrix(matrix_to_wxyz(m)), m, atol=1e-12)


def test_polygon_mask_pixel_centre_rule():
    # a square covering u, v ∈ [2, 5]: pixel centres 2.5, 3.5, 4.5 are inside → 3 × 3 pixels
    crop = convex_polygon_mask(np.array([[2, 2], [5, 2], [5, 5], [2, 5.0]]), 10, 10)
    full = np.zeros((10, 10), bool)
    full[crop.r0:crop.r0 + crop.mask.shape[0], crop.c0:crop.c0 + crop.mask.shape[1]] = crop.mask
    assert full.sum() == 9 and full[2:5, 2:5].all()
    assert convex_polygon_mask(np.array([[1, 1], [2, 2], [3, 3.0]]), 10, 10) is None       # degenerate
    assert convex_polygon_mask(np.array([[-9, -9], [-5, -9], [-5, -5.0]]), 10, 10) is None  # off image


def test_silhouettes_match_isolated_render(small_dataset):
    """Every object of a hard scene, alone in the bin, renders exactly as its projected silhouette."""
    from mqa_rl.sim.scene import build_world

    scene = next(s for s in small_dataset.scenes if s.difficulty == "hard")
    assets = small_dataset.assets(scene)
    cam = small_dataset.camera
    sil = silhouettes([list(a.collision_parts) for a in assets], scene.poses, cam)
    world = build_world(assets, scene.poses, camera=cam)
    ious = []
    for i, body in enumerate(world.objects):
        for j, other in enumerate(world.objects):         # hide every other object
            other.find_component_by_type(__import__("sapien").render.RenderBodyComponent).visibility = float(i == j)
        _, _, seg = world.render()
        mask = seg == body.per_scene_id
        union = (mask | sil[i]).sum()
        if union:
            ious.append((mask & sil[i]).sum() / union)
    assert min(ious) >= 0.99, f"worst IoU {min(ious):.4f}"
