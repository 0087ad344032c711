"""tools/carry_store.py carries a frame store losslessly in bounded shards, and the perception trainer needs no simulator."""

import json
import subprocess
import sys
import tarfile
from pathlib import Path

import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.frame_records import load_frames
from mqa_rl.collectors.store import EpisodeStore, load_records

REPO = Path(__file__).resolve().parents[2]
TOOL = [sys.executable, str(REPO / "tools" / "carry_store.py")]


def _store(root: Path) -> Path:
    g = torch.Generator().manual_seed(0)
    with EpisodeStore(root, {"slots": 12, "kind": "perception_frames", "plan": {"size": 32}}) as store:
        for c in range(3):
            n = 4
            store.append(TensorDict({keys.SLOT: torch.arange(c * n, (c + 1) * n),
                                     keys.RGB: torch.randint(0, 255, (n, 3, 32, 32), generator=g, dtype=torch.uint8),
                                     keys.DEPTH: torch.rand(n, 1, 32, 32, generator=g).half(),
                                     keys.SCENE: torch.full((n,), c)}, batch_size=[n]))
    return root


def test_a_store_travels_in_shards_and_comes_back_identical_without_the_dropped_field(tmp_path):
    src = _store(tmp_path / "frames")
    out = tmp_path / "carry"
    subprocess.run([*TOOL, "pack", str(src), "--out", str(out), "--drop", "depth", "--shard-mib", "0.01"], check=True)
    shards = sorted(out.glob("shard-*.tar"))
    assert len(shards) == 3                                     # a shard per chunk at this bound
    subprocess.run([*TOOL, "unpack", *map(str, shards), "--into", str(tmp_path / "there")], check=True)
    back, ref = load_records(tmp_path / "there" / "frames"), load_records(src)
    assert keys.DEPTH not in back.keys()
    for k in (keys.SLOT, keys.RGB, keys.SCENE):
        assert torch.equal(back[k], ref[k]), k
    assert json.loads((tmp_path / "there" / "frames" / "meta.json").read_text())["slots"] == 12
    assert load_frames([tmp_path / "there" / "frames"], [keys.RGB, keys.SCENE]).shape[0] == 12


def test_a_damaged_shard_is_refused_and_leaves_no_chunk(tmp_path):
    src = _store(tmp_path / "frames")
    out = tmp_path / "carry"
    subprocess.run([*TOOL, "pack", str(src), "--out", str(out), "--shard-mib", "100"], check=True)
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["frames/chunk-00000/rgb.memmap"]["sha256"] = "0" * 64   # the bytes no longer match what was packed
    (out / "manifest.json").write_text(json.dumps(manifest))
    run = subprocess.run([*TOOL, "unpack", str(out / "shard-000.tar"), "--into", str(tmp_path / "there")],
                         capture_output=True, text=True)
    assert run.returncode != 0 and "SHA-256" in run.stderr and "pack it again" in run.stderr
    assert not list((tmp_path / "there" / "frames").glob("chunk-*"))
    with tarfile.open(out / "shard-000.tar") as tar:
        assert all(m.name.endswith(".xz") for m in tar)


def test_the_perception_trainer_imports_without_the_simulator_ray_or_wandb():
    """A GPU machine without SAPIEN trains the perception from carried frames (docs/perception.md)."""
    code = ("import sys, importlib.util\n"
            "for m in ('sapien', 'ray', 'wandb', 'gradio'): sys.modules[m] = None\n"
            f"spec = importlib.util.spec_from_file_location('tp', {str(REPO / 'recipes' / 'train_perception.py')!r})\n"
            "spec.loader.exec_module(importlib.util.module_from_spec(spec))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert run.returncode == 0, run.stderr[-2000:]


def _crafted(tmp_path, names, manifest_extra=None):
    """A shard set from someone else: members named ``names`` (their SHA-256 right), and a manifest."""
    import hashlib
    import io
    import lzma

    out = tmp_path / "crafted"
    out.mkdir(parents=True)
    manifest = dict(manifest_extra or {})
    with tarfile.open(out / "shard-000.tar", "w") as tar:
        for name in names:
            raw = b"print('planted')\n"
            manifest[name] = {"sha256": hashlib.sha256(raw).hexdigest()}
            data = lzma.compress(raw)
            info = tarfile.TarInfo(f"{name}.xz")
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    (out / "manifest.json").write_text(json.dumps(manifest))
    return out / "shard-000.tar"


def test_unpack_refuses_names_outside_into_and_writes_or_deletes_nothing(tmp_path):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep.py").write_text("original\n")
    into = tmp_path / "there"
    for names, extra in ((["../victim/keep.py"], None), ([f"{victim}/x/keep.py"], None),
                         (["frames/chunk-00000/rgb.memmap"], {"../victim/meta.json": {"inline": "{}"}}),
                         (["frames/x"], None)):                     # two names deep: it would replace the store's folder
        shard = _crafted(tmp_path / str(abs(hash(str(names) + str(extra)))), names, extra)
        run = subprocess.run([*TOOL, "unpack", str(shard), "--into", str(into)], capture_output=True, text=True)
        assert run.returncode != 0 and "refused" in run.stderr, (names, run.stderr)
        assert (victim / "keep.py").read_text() == "original\n" and sorted(p.name for p in victim.iterdir()) == ["keep.py"]
        assert not into.exists() or not any(into.rglob("*"))
