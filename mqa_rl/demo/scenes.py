"""The scene gallery: every scene's first camera image, rendered once and cached on disk.

The first image is what the env shows at reset (the scene rebuilt from its stored poses by the same
``build_world``, seen by the env's camera). Rendering all 100 scenes takes ~10 s on 2 cores, so the
PNGs are kept under ``cache_dir/<digest of the dataset's manifest and the camera>/`` and a later
server start reads them back.
"""

from __future__ import annotations

import hashlib
import json
import logging
from dataclasses import dataclass
from pathlib import Path

import cv2

from mqa_rl.data.dataset import LEVELS, SPLITS, MQADataset
from mqa_rl.files import write_atomic
from mqa_rl.sim.geometry import CameraSpec
from mqa_rl.sim.scene import build_world

log = logging.getLogger(__name__)
ALL = "all"


@dataclass(frozen=True)
class SceneCard:
    id: str
    difficulty: str
    split: str
    objects: int
    image: Path          # PNG of the first camera image

    @property
    def caption(self) -> str:
        return f"{self.id} · {self.difficulty} · {self.split}"

    @property
    def short_caption(self) -> str:              # what fits under a thumbnail
        return f"{self.id.rsplit('_', 1)[-1]} {self.difficulty}"


class SceneCatalog:
    """Scene cards with their first images, filtered by level and split for the gallery."""

    def __init__(self, dataset: MQADataset, camera: CameraSpec, cache_dir: str | Path):
        self.dataset = dataset
        manifest = (dataset.root / "manifest.json").read_bytes()
        key = hashlib.sha256(manifest + json.dumps(vars(camera), sort_keys=True).encode()).hexdigest()[:16]
        self.directory = Path(cache_dir).expanduser() / f"scenes-{key}"
        self.directory.mkdir(parents=True, exist_ok=True)
        self.cards: dict[str, SceneCard] = {}
        rendered = 0
        for scene in dataset.scenes:
            path = self.directory / f"{scene.id}.png"
            if not path.exists():
                self._render(scene, camera, path)
                rendered += 1
            self.cards[scene.id] = SceneCard(scene.id, scene.difficulty, scene.split, len(scene.objects), path)
        log.info("scene images: %d rendered, %d from the cache %s", rendered, len(self.cards) - rendered, self.directory)

    def _render(self, scene, camera: CameraSpec, path: Path) -> None:
        world = build_world(self.dataset.assets(scene), scene.poses, bin_spec=self.dataset.bin, camera=camera)
        rgb = world.render()[0]
        ok, png = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        if not ok:
            raise OSError(f"OpenCV cannot encode the first image of {scene.id} as PNG")
        try:
            write_atomic(path, png.tobytes())                               # another server may share the cache
        except OSError as error:
            raise OSError(f"cannot write {path}; is the demo's cache_dir writable?") from error

    def select(self, level: str = ALL, split: str = ALL) -> list[SceneCard]:
        """Cards of one level and split (``"all"`` for either); unknown names are refused."""
        if level != ALL and level not in LEVELS:
            raise ValueError(f"unknown level {level!r}; choose among {[ALL, *LEVELS]}")
        if split != ALL and split not in SPLITS:
            raise ValueError(f"unknown split {split!r}; choose among {[ALL, *SPLITS]}")
        return [c for c in self.cards.values() if level in (ALL, c.difficulty) and split in (ALL, c.split)]

    def card(self, scene_id: str) -> SceneCard:
        try:
            return self.cards[scene_id]
        except KeyError:
            raise KeyError(f"unknown scene {scene_id!r}; scenes run {next(iter(self.cards))} … "
                           f"{next(reversed(self.cards))}") from None
