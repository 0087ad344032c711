"""Object assets as the simulator and the dataset see them: coloured visual meshes + convex parts.

Generated objects (``mqa_rl.data.objects``) have one convex part per visual piece. Users with real
meshes (a folder ``<class>/<instance>/*.obj|ply|stl|glb``, YCB-style) get an asset whose visual is
their mesh and whose collision is a convex decomposition (``coacd`` when installed, else a single
convex hull with a warning). Vertices are kept at float32 precision, the precision PhysX and the
on-disk PLY files use, so an asset survives a save/load round trip exactly.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")


@dataclass(frozen=True)
class VisualMesh:
    vertices: np.ndarray           # [n, 3] float64 (float32-exact), object frame, metres
    faces: np.ndarray              # [m, 3] int64
    color: tuple[float, float, float, float]


@dataclass(frozen=True)
class ObjectAsset:
    """Everything the simulator needs about one object instance."""

    class_name: str
    instance_id: int
    visuals: tuple[VisualMesh, ...]
    collision_parts: tuple[np.ndarray, ...]     # vertices [k, 3] of each convex part
    density: float                              # kg/m^3

    @property
    def name(self) -> str:
        return f"{self.class_name}_{self.instance_id}"

    @property
    def volume(self) -> float:
        return float(sum(trimesh.convex.convex_hull(p).volume for p in self.collision_parts))

    @property
    def mass(self) -> float:
        """Density × summed part volumes: what PhysX computes from the attached shapes."""
        return self.density * self.volume

    @property
    def dimensions(self) -> np.ndarray:
        pts = np.concatenate(self.collision_parts)
        return pts.max(0) - pts.min(0)

    # ------------------------------------------------------------------------------- builders
    @classmethod
    def from_model(cls, model) -> "ObjectAsset":
        """From a generated ``mqa_rl.data.objects.ObjectModel``: each convex part is also a visual."""
        visuals, parts = [], []
        for part in model.parts:
            v = _f32(part.mesh.vertices)
            visuals.append(VisualMesh(v, np.asarray(part.mesh.faces, np.int64), tuple(float(c) for c in part.color)))
            parts.append(v)
        return cls(model.class_name, int(model.instance_id), tuple(visuals), tuple(parts), float(model.density))

    # ------------------------------------------------------------------------------- disk
    def save(self, folder: Path) -> dict[str, bytes]:
        """The asset as files (name → bytes) for the dataset writer: ``visual_XX.ply`` (with face
        colours), ``collision_XX.ply`` (convex parts). Byte-identical for identical assets."""
        files = {}
        for i, v in enumerate(self.visuals):
            m = trimesh.Trimesh(v.vertices, v.faces, process=False)
            m.visual.face_colors = np.round(np.asarray(v.color) * 255).astype(np.uint8)
            files[f"{folder}/visual_{i:02d}.ply"] = trimesh.exchange.ply.export_ply(m, encoding="binary")
        for i, p in enumerate(self.collision_parts):
            hull = trimesh.convex.convex_hull(p)
            files[f"{folder}/collision_{i:02d}.ply"] = trimesh.exchange.ply.export_ply(hull, encoding="binary")
        return files

    @classmethod
    def load(cls, folder: Path, class_name: str, instance_id: int, density: float) -> "ObjectAsset":
        folder = Path(folder)
        visuals, parts = [], []
        for f in sorted(folder.glob("visual_*.ply")):
            m = _read_ply(f)
            color = tuple(float(c) / 255 for c in m.visual.face_colors[0]) if len(m.faces) else (0.5, 0.5, 0.5, 1.0)
            visuals.append(VisualMesh(_f32(m.vertices), np.asarray(m.faces, np.int64), color))
        for f in sorted(folder.glob("collision_*.ply")):
            parts.append(_f32(_read_ply(f).vertices))
        if not visuals or not parts:
            raise ValueError(f"object folder {folder} has no visual_*.ply or collision_*.ply files")
        return cls(class_name, instance_id, tuple(visuals), tuple(parts), density)


def _f32(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float32).astype(np.float64)


def _read_ply(path: Path) -> trimesh.Trimesh:
    data = Path(path).read_bytes()
    return trimesh.load(io.BytesIO(data), file_type="ply", process=False)


# ----------------------------------------------------------------------------------- user meshes
def convex_decomposition(mesh: trimesh.Trimesh, max_parts: int = 16) -> list[np.ndarray]:
    """Convex parts of a (possibly non-convex) mesh: CoACD when installed, else its convex hull."""
    try:
        import coacd
    except ImportError:
        warnings.warn(
            "coacd is not installed: using one convex hull per mesh, which fills holes and concavities "
            "(pip install 'mqa_rl[meshes]' for an exact convex decomposition)",
            stacklevel=2,
        )
        return [_f32(mesh.convex_hull.vertices)]
    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(mesh.vertices, mesh.faces), threshold=0.05, max_convex_hull=max_parts, seed=0)
    return [_f32(v) for v, _ in parts]


def load_mesh_folder(root: Path, density: float = 600.0, scale: float = 1.0) -> list[ObjectAsset]:
    """Assets from ``root/<class>/<instance>/<mesh files>`` (classes and instances in sorted order).

    Each instance's mesh files are merged, scaled by ``scale`` (use 0.001 for millimetre meshes),
    re-centred on their bounding box, and decomposed into convex parts for collision.
    """
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"mesh folder {root} does not exist; expected <class>/<instance>/*.obj")
    assets = []
    for class_dir in sorted(p for p in root.iterdir() if p.is_dir()):
        for inst, inst_dir in enumerate(sorted(p for p in class_dir.iterdir() if p.is_dir())):
            files = sorted(f for f in inst_dir.iterdir() if f.suffix.lower() in MESH_SUFFIXES)
            if not files:
                raise ValueError(f"{inst_dir} has no mesh file ({', '.join(MESH_SUFFIXES)})")
            meshes = [trimesh.load(f, force="mesh", process=True) for f in files]
            mesh = trimesh.util.concatenate(meshes)
            mesh.apply_scale(scale)
            mesh.apply_translation(-mesh.bounds.mean(axis=0))
            rgba = np.asarray(mesh.visual.main_color if hasattr(mesh.visual, "main_color") else [128, 128, 128, 255]) / 255
            visual = VisualMesh(_f32(mesh.vertices), np.asarray(mesh.faces, np.int64), tuple(float(c) for c in rgba))
            assets.append(ObjectAsset(class_dir.name, inst, (visual,), tuple(convex_decomposition(mesh)), density))
    if not assets:
        raise ValueError(f"mesh folder {root} holds no <class>/<instance>/ folders")
    return assets
