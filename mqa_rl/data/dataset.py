"""Generate the MQA dataset (objects, settled scenes, questions, vocabularies) and load it back.

>>> from mqa_rl.data import generate_dataset, MQADataset
>>> ds = generate_dataset("data/mqa", seed=0)                     # doctest: +SKIP
>>> ds = MQADataset("data/mqa"); ds.classes[:2], len(ds.scenes)    # doctest: +SKIP
"""

from __future__ import annotations

import hashlib
import json
import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import mqa_rl
from mqa_rl.data.questions import QUESTION_TYPES, Question, question_text, scene_questions, under_matrix
from mqa_rl.data.arguments import scene_plan, seed_and_fraction
from mqa_rl.data.storage import DatasetError, check_out_dir, dumps_json, read_verified, write_dataset_atomically
from mqa_rl.data.vocab import ANSWERS, Vocabulary
from mqa_rl.sim.assets import ObjectAsset
from mqa_rl.sim.geometry import BinSpec, CameraSpec, framing_fovy

DEFAULT_NUM_SCENES = {"easy": 30, "medium": 30, "hard": 40}
LEVELS = tuple(DEFAULT_NUM_SCENES)                               # difficulty levels, easiest first
SPLITS = ("train", "test")


@dataclass(frozen=True, slots=True)
class SceneObject:
    class_name: str
    instance_id: int
    pose: tuple[float, ...]          # x, y, z, qw, qx, qy, qz (world, metres)

    @property
    def name(self) -> str:
        return f"{self.class_name}_{self.instance_id}"


@dataclass(frozen=True)
class Scene:
    id: str
    difficulty: str                  # easy / medium / hard
    split: str                       # train / test
    objects: tuple[SceneObject, ...]

    @property
    def poses(self) -> np.ndarray:
        return np.array([o.pose for o in self.objects], dtype=np.float64)


# ----------------------------------------------------------------------------------------- generation
def _phrases_for(name: str) -> tuple[str, str]:
    words = name.replace("_", " ")
    return (("an " if words[0] in "aeiou" else "a ") + words, words + "s")


def _library(library) -> tuple[list[ObjectAsset], dict[str, tuple[str, str]]]:
    """The default procedural library, or user meshes from a folder, or a list of assets."""
    if library is None:
        from mqa_rl.data import objects

        return [ObjectAsset.from_model(m) for m in objects.make_library()], dict(objects.CLASS_PHRASES)
    if isinstance(library, (str, Path)):
        from mqa_rl.sim.assets import load_mesh_folder

        library = load_mesh_folder(Path(library))
    assets = list(library)
    return assets, {a.class_name: _phrases_for(a.class_name) for a in assets}


def _bin(bin_spec) -> BinSpec:
    """A valid ``BinSpec`` (default when None); a mapping of its fields is accepted too (configs)."""
    if bin_spec is None:
        return BinSpec()
    if isinstance(bin_spec, dict):
        unknown = set(bin_spec) - {"inner_size", "wall_height", "wall_thickness"}
        if unknown:
            raise ValueError(f"unknown bin field(s) {sorted(unknown)}; allowed: inner_size, wall_height, wall_thickness")
        bin_spec = BinSpec(**bin_spec)
    values = (bin_spec.inner_size, bin_spec.wall_height, bin_spec.wall_thickness)
    if not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in values):
        raise ValueError(f"bin sizes must be positive finite metres, got {bin_spec}")
    if bin_spec.inner_size < 0.2 or bin_spec.wall_height < 0.1:
        raise ValueError(f"a bin of {bin_spec.inner_size} m with {bin_spec.wall_height} m walls cannot hold the "
                         "scenes' 20-50 real-size objects; use inner_size ≥ 0.2 and wall_height ≥ 0.1")
    return bin_spec


def _split(rng: np.random.Generator, n: int, train_fraction: float) -> list[str]:
    order = rng.permutation(n)
    n_train = int(round(train_fraction * n))
    split = ["test"] * n
    for i in order[:n_train]:
        split[i] = "train"
    return split


def generate_dataset(
    out_dir,
    *,
    seed: int = 0,
    num_scenes: dict[str, int] | None = None,
    library=None,
    train_fraction: float = 0.7,
    objects_per_scene: dict[str, int] | None = None,
    bin_spec: BinSpec | None = None,
    overwrite: bool = False,
    progress: bool = False,
    workers: int = 1,
) -> "MQADataset":
    """Build the dataset into ``out_dir`` (atomically) and return it loaded.

    ``num_scenes`` maps difficulty (easy / medium / hard = 20 / 35 / 50 objects) to a scene count;
    the split is by scene, stratified by difficulty. ``library`` is None (the 60 procedural objects),
    a folder of user meshes ``<class>/<instance>/*.obj``, or a list of ``ObjectAsset``.
    ``objects_per_scene`` overrides the paper's object counts per level (for sparser or denser
    scenes). ``bin_spec`` changes the bin (default: 40 × 40 cm, 45 cm walls); the camera is framed
    on its rim. Everything derives from ``seed``: the same seed gives the same files, byte for byte, whatever
    ``workers`` (processes settling scenes side by side: each scene depends on the seed and its index alone).
    """
    from mqa_rl.data.scenes import DIFFICULTIES, drop_config
    from mqa_rl.data.stats import answer_statistics

    num_scenes, per_level = scene_plan(DEFAULT_NUM_SCENES if num_scenes is None else num_scenes,
                                       objects_per_scene, DIFFICULTIES)
    seed, train_fraction = seed_and_fraction(seed, train_fraction)
    bin_spec = _bin(bin_spec)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers={workers!r} must be a positive integer (processes settling scenes; 2 on 2 cores)")
    check_out_dir(out_dir, overwrite)                     # before the work, not after it
    assets, phrases = _library(library)
    names = [a.name for a in assets]
    if len(set(names)) != len(names):
        raise ValueError("object library has duplicate (class, instance) pairs")
    classes = tuple(dict.fromkeys(a.class_name for a in assets))
    per_class = Counter(a.class_name for a in assets)
    if max(per_class.values()) > 3:
        raise ValueError("at most 3 instances per class (COUNTING answers are 0-3)")
    for level, count in num_scenes.items():
        if count and not 1 <= per_level[level] <= len(assets):
            raise ValueError(f"{level} scenes need {per_level[level]} objects; the library has {len(assets)}")

    camera = CameraSpec(fovy_deg=framing_fovy(bin_spec))
    plan = [(level, i) for level in DIFFICULTIES for i in range(num_scenes.get(level, 0))]
    split_of = {}
    for k, level in enumerate(DIFFICULTIES):
        ids = [j for j, (lv, _) in enumerate(plan) if lv == level]
        for j, s in zip(ids, _split(np.random.default_rng([seed, 1_000_000 + k]), len(ids), train_fraction)):
            split_of[j] = s

    jobs = [(seed, j, per_level[level]) for j, (level, _) in enumerate(plan)]
    settled_scenes = _settle_all(jobs, assets, bin_spec, camera, workers, progress)
    scenes, raw_questions, attempts = [], [], []
    for j, (indices, poses, tries, under) in enumerate(settled_scenes):
        level, _ = plan[j]
        attempts.append(tries)
        scene_id = f"scene_{j:03d}"
        chosen = [assets[i] for i in indices]
        objs = [
            {"class": a.class_name, "instance": a.instance_id, "pose": [float(x) for x in p]}
            for a, p in zip(chosen, poses)
        ]
        scenes.append({"id": scene_id, "difficulty": level, "split": split_of[j], "objects": objs})
        raw_questions += [(scene_id, *q) for q in scene_questions(scene_id, [a.class_name for a in chosen], under, classes, phrases)]

    texts = [question_text(t, c, phrases) for _, _, t, c, _ in raw_questions]
    vocab = Vocabulary.build(texts)
    lines = []
    for (scene_id, qid, qtype, qclasses, answer), text in zip(raw_questions, texts):
        q = {"id": qid, "scene_id": scene_id, "type": qtype, "text": text, "tokens": vocab.encode(text),
             "classes": list(qclasses), "answer": answer}
        lines.append(json.dumps(q, sort_keys=True, separators=(",", ":")))
    level_of = {s["id"]: s["difficulty"] for s in scenes}
    stats = answer_statistics([(level_of[s], t, a) for s, _, t, _, a in raw_questions])

    files: dict[str, bytes] = {}
    object_rows = []
    for a in assets:
        folder = f"objects/{a.class_name}/{a.instance_id}"
        files.update(a.save(folder))
        object_rows.append({"class": a.class_name, "instance": a.instance_id, "density": a.density, "folder": folder,
                            "mass": round(a.mass, 6), "dimensions": [round(float(d), 6) for d in a.dimensions]})
    files["objects.json"] = dumps_json({"classes": [{"name": c, "singular": phrases[c][0], "plural": phrases[c][1]} for c in classes],
                                        "objects": object_rows})
    files["scenes.json"] = dumps_json(scenes)
    files["questions.jsonl"] = ("\n".join(lines) + "\n").encode()
    files["vocab.json"] = dumps_json({"questions": list(vocab.itos), "answers": list(ANSWERS)})
    files["stats.json"] = dumps_json(stats)
    manifest = {
        "generator": f"mqa_rl {mqa_rl.__version__}",
        "seed": seed,
        "config": {"num_scenes": num_scenes, "objects_per_scene": per_level, "train_fraction": train_fraction,
                   "bin": vars(bin_spec), "camera": vars(camera), "drop": drop_config()},
        "counts": {"objects": len(assets), "classes": len(classes), "scenes": len(scenes), "questions": len(lines)},
        "drop_attempts": {"total": int(sum(attempts)), "max": int(max(attempts, default=0))},
    }
    write_dataset_atomically(Path(out_dir), files, manifest, overwrite=overwrite)
    return MQADataset(out_dir)


_WORKER: dict = {}        # the library, bin and camera of a settling process (set once by _init_worker)


def _init_worker(assets, bin_spec, camera) -> None:
    import mqa_rl  # noqa: F401  (a spawned process: the same thread settings as the parent)

    _WORKER.update(assets=assets, bin_spec=bin_spec, camera=camera)


def _settle_one(job: tuple[int, int, int]):
    """Scene ``j`` of ``seed``: its objects' indices, settled poses, drop attempts and which object lies under
    which (from the silhouettes). Depends on ``(seed, j)`` alone, so scenes settle in any process and order."""
    from mqa_rl.data.scenes import settle_scene
    from mqa_rl.sim.silhouette import silhouettes

    seed, j, n_objects = job
    assets, bin_spec, camera = _WORKER["assets"], _WORKER["bin_spec"], _WORKER["camera"]
    rng = np.random.default_rng([seed, j])
    indices = np.sort(rng.choice(len(assets), n_objects, replace=False))
    settled = settle_scene(assets, indices, rng, bin_spec)
    chosen = [assets[i] for i in indices]
    sil = silhouettes([list(a.collision_parts) for a in chosen], settled.poses, camera)
    return indices, settled.poses, settled.attempts, under_matrix(sil, settled.poses[:, 2])


def _settle_all(jobs, assets, bin_spec, camera, workers: int, show: bool) -> list:
    """Every planned scene settled, in plan order: in this process, or in ``workers`` spawned processes."""
    from mqa_rl.progress import progress

    def shown(results):
        return progress(results, total=len(jobs), desc="settling scenes", unit="scene") if show else results

    if workers == 1 or len(jobs) < 2:
        _init_worker(assets, bin_spec, camera)
        return list(shown(map(_settle_one, jobs)))
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(min(workers, len(jobs)), mp_context=multiprocessing.get_context("spawn"),
                             initializer=_init_worker, initargs=(assets, bin_spec, camera)) as pool:
        return list(shown(pool.map(_settle_one, jobs)))


# ----------------------------------------------------------------------------------------- loading
def _chosen(value, allowed: tuple[str, ...], what: str) -> set[str]:
    """A filter's names: None or empty → all of ``allowed``; a name outside ``allowed`` is refused."""
    if value is None:
        return set(allowed)
    try:
        chosen = {value} if isinstance(value, str) else set(value)
    except TypeError:
        raise ValueError(f"a {what} filter is a name or a list of names from {list(allowed)}, got {value!r}") from None
    bad = chosen - set(allowed)
    if bad:
        raise ValueError(f"unknown {what} {sorted(bad, key=str)}; allowed: {list(allowed)}")
    return chosen or set(allowed)


class MQADataset:
    """A generated dataset, verified against its manifest on load.

    ``classes`` (names), ``scenes`` (``Scene``), ``questions`` (``Question``), ``vocab`` (question
    tokens), ``answers`` (answer vocabulary), ``stats``; ``assets(scene)`` gives the simulator
    assets of a scene's objects, in the scene's order.
    """

    def __init__(self, root):
        self.root = Path(root)
        self.manifest, data = read_verified(self.root)
        try:
            objects = json.loads(data["objects.json"])
            vocab = json.loads(data["vocab.json"])
            self.classes: tuple[str, ...] = tuple(c["name"] for c in objects["classes"])
            self.phrases = {c["name"]: (c["singular"], c["plural"]) for c in objects["classes"]}
            self._object_rows = {(o["class"], o["instance"]): o for o in objects["objects"]}
            self.vocab = Vocabulary(tuple(vocab["questions"]))
            self.answers: tuple[str, ...] = tuple(vocab["answers"])
            self.scenes: list[Scene] = [
                Scene(s["id"], s["difficulty"], s["split"],
                      tuple(SceneObject(o["class"], int(o["instance"]), tuple(o["pose"])) for o in s["objects"]))
                for s in json.loads(data["scenes.json"])
            ]
            self.questions: list[Question] = [
                Question(q["id"], q["scene_id"], q["type"], q["text"], tuple(q["tokens"]), tuple(q["classes"]), q["answer"])
                for q in map(json.loads, data["questions.jsonl"].decode().splitlines())
            ]
            self.stats = json.loads(data["stats.json"])
        except (KeyError, ValueError, TypeError) as e:
            raise DatasetError(f"{self.root} is corrupt ({type(e).__name__}: {e}); regenerate it") from None
        self._scene_by_id = {s.id: s for s in self.scenes}
        self._question_by_id = {q.id: q for q in self.questions}
        self._assets: dict[tuple[str, int], ObjectAsset] = {}

    def __repr__(self) -> str:
        return f"MQADataset({str(self.root)!r}, scenes={len(self.scenes)}, questions={len(self.questions)})"

    @property
    def camera(self) -> CameraSpec:
        """The camera the SPATIAL answers were computed with."""
        return CameraSpec(**self.manifest["config"]["camera"])

    @property
    def bin(self) -> BinSpec:
        return BinSpec(**self.manifest["config"]["bin"])

    def scene(self, scene_id: str) -> Scene:
        try:
            return self._scene_by_id[scene_id]
        except KeyError:
            raise KeyError(f"unknown scene id {scene_id!r}; ids run {self.scenes[0].id} … {self.scenes[-1].id}") from None

    def question(self, question_id: str) -> Question:
        try:
            return self._question_by_id[question_id]
        except KeyError:
            raise KeyError(f"unknown question id {question_id!r}; ids look like {self.questions[0].id!r}") from None

    def select(self, split=None, difficulties=None, types=None) -> list[Question]:
        """Questions filtered by split ("train"/"test"), difficulty levels and question types.

        Each filter is None (all), one name or a list of names; an unknown name raises ``ValueError``.
        """
        splits = _chosen(split, SPLITS, "split")
        levels = _chosen(difficulties, LEVELS, "difficulty")
        kinds = _chosen(types, QUESTION_TYPES, "question type")
        return [
            q for q in self.questions
            if q.type in kinds and self._scene_by_id[q.scene_id].split in splits
            and self._scene_by_id[q.scene_id].difficulty in levels
        ]

    def asset(self, class_name: str, instance_id: int) -> ObjectAsset:
        key = (class_name, instance_id)
        if key not in self._assets:
            row = self._object_rows.get(key)
            if row is None:
                raise KeyError(f"unknown object {class_name}_{instance_id}; classes: {list(self.classes)}")
            self._assets[key] = ObjectAsset.load(self.root / row["folder"], class_name, instance_id, float(row["density"]))
        return self._assets[key]

    def assets(self, scene: Scene) -> list[ObjectAsset]:
        return [self.asset(o.class_name, o.instance_id) for o in scene.objects]

    def summary(self) -> str:
        from mqa_rl.data.stats import format_statistics

        levels = Counter((s.difficulty, s.split) for s in self.scenes)
        rows = [f"MQA dataset at {self.root} (schema {self.manifest['schema_version']}, seed {self.manifest['seed']})",
                f"  {len(self._object_rows)} objects in {len(self.classes)} classes: {', '.join(self.classes)}",
                f"  {len(self.scenes)} scenes:"]
        for level in LEVELS:
            rows.append(f"    {level:<6} train {levels[(level, 'train')]:>3}  test {levels[(level, 'test')]:>3}")
        by_type = Counter(q.type for q in self.questions)
        rows.append(f"  {len(self.questions)} questions: " + ", ".join(f"{t} {by_type[t]}" for t in QUESTION_TYPES))
        rows.append(f"  vocabulary: {len(self.vocab)} words, answers {list(self.answers)}")
        rows.append(format_statistics(self.stats))
        return "\n".join(rows)


def dataset_fingerprint(root: str | Path) -> str:
    """SHA-256 of the dataset's manifest (which lists the SHA-256 of every file)."""
    return hashlib.sha256((Path(root) / "manifest.json").read_bytes()).hexdigest()
