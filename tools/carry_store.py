"""Carry an ``EpisodeStore`` (e.g. perception frames) to another machine in xz shards of bounded size, losslessly.

Frames are rendered where the simulator runs (CPU) and trained on where a GPU is; a lent GPU machine
takes a bounded working tree per call, so the store travels in shards over several calls:

    python tools/carry_store.py pack runs/perception/frames224 runs/perception/frames224b --out .carry/frames \
        --drop depth --shard-mib 30            # here: ~9.5 kB per 224-px frame without depth (~200 kB raw)
    python tools/carry_store.py unpack .carry/frames/shard-003.tar --into .   # there, once per shard

Every file is xz-compressed on its own and checked against its SHA-256 (``manifest.json``) when it
is unpacked; a chunk folder appears only once all its files are in (written to a hidden folder and
renamed), so a store that is still arriving holds only whole chunks. ``--drop KEY`` leaves a field
out (its chunk ``meta.json`` entries too), e.g. the depth images a perception that reads only rgb
never loads. Standard library only, so that it runs on a machine that has nothing else installed yet.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import lzma
import multiprocessing as mp
import os
import shutil
import sys
import tarfile
from pathlib import Path


def _pack_chunk(args):
    chunk, store_name, drop, preset = args
    members = []
    meta = json.loads((chunk / "meta.json").read_text())
    for key in drop:
        meta.pop(key, None)
    files = {"meta.json": json.dumps(meta).encode()}
    for path in sorted(chunk.iterdir()):
        if path.suffix == ".memmap" and path.stem not in drop:
            files[path.name] = path.read_bytes()
    for name, raw in files.items():
        rel = f"{store_name}/{chunk.name}/{name}"
        members.append((rel, hashlib.sha256(raw).hexdigest(), len(raw), lzma.compress(raw, preset=preset)))
    return chunk.name, store_name, members


def pack(stores: list[Path], out: Path, drop: list[str], shard_mib: float, preset: int, workers: int) -> None:
    out.mkdir(parents=True, exist_ok=True)
    manifest: dict[str, dict] = {}
    jobs = []
    for store in stores:
        if not (store / "meta.json").is_file():
            sys.exit(f"{store} is not a store (no meta.json)")
        manifest[f"{store.name}/meta.json"] = {"inline": (store / "meta.json").read_text()}
        jobs += [(c, store.name, drop, preset) for c in sorted(store.glob("chunk-*")) if c.is_dir()]
    if not jobs:
        sys.exit(f"no chunk in {[str(s) for s in stores]}: collect the frames first")
    limit = int(shard_mib * 2**20)
    index, shard, shard_bytes = -1, None, 0

    def close_shard():
        shard.close()
        os.replace(out / f".shard-{index:03d}.tar.tmp", out / f"shard-{index:03d}.tar")

    with mp.Pool(workers) as pool:
        for i, (chunk, store_name, members) in enumerate(pool.imap(_pack_chunk, jobs)):
            size = sum(len(m[3]) + 1024 for m in members)
            if shard is None or shard_bytes + size > limit:
                if shard is not None:
                    close_shard()
                index, shard_bytes = index + 1, 0
                shard = tarfile.open(out / f".shard-{index:03d}.tar.tmp", "w")
            for rel, sha, n, data in members:
                info = tarfile.TarInfo(rel + ".xz")
                info.size = len(data)
                shard.addfile(info, io.BytesIO(data))
                manifest[rel] = {"sha256": sha, "bytes": n, "shard": index}
            shard_bytes += size
            print(f"\r{i + 1}/{len(jobs)} chunks, {index + 1} shard(s)", end="", flush=True)
    close_shard()
    (out / "manifest.json").write_text(json.dumps(manifest, indent=0))
    total = sum(p.stat().st_size for p in out.glob("shard-*.tar"))
    print(f"\n{len(jobs)} chunks of {len(stores)} store(s) in {index + 1} shard(s), {total / 2**20:.1f} MiB")


def inside(into: Path, rel: str, where: str, depth: int = 2) -> Path:
    """``into / rel`` when ``rel`` is a relative path that stays under ``into``, at least ``depth`` names deep (a
    store's file: 2, a chunk's file: 3, whose chunk folder is replaced); else exit naming it, as tarfile's
    extraction filters do: a shard set from someone else must not write or delete outside ``--into``."""
    path = Path(rel)
    if (not rel or path.is_absolute() or ".." in path.parts or len(path.parts) < depth or "\\" in rel
            or not (into / path).resolve().is_relative_to(into.resolve())):
        sys.exit(f"{where}: the entry {rel!r} would be written outside --into {into} (an absolute path, '..' or a "
                 f"top-level name): refused; nothing was unpacked from it. Pack the store again, or ask who sent it")
    return into / path


def unpack(shards: list[Path], into: Path, manifest_path: Path | None) -> None:
    manifest_path = manifest_path or shards[0].parent / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    for rel in manifest:                                       # every name checked before anything is written
        inside(into, rel, str(manifest_path))
    for rel, entry in manifest.items():                        # the stores' own meta.json travel inline
        if "inline" in entry:
            (into / rel).parent.mkdir(parents=True, exist_ok=True)
            (into / rel).write_text(entry["inline"])
    for shard in shards:
        chunks: dict[Path, dict[str, bytes]] = {}
        with tarfile.open(shard) as tar:
            members = tar.getmembers()
            for member in members:
                if not member.isfile():
                    sys.exit(f"{shard}: {member.name!r} is not a regular file (a link or device): refused")
                inside(into, member.name.removesuffix(".xz"), str(shard), depth=3)
            for member in members:
                rel = member.name.removesuffix(".xz")
                raw = lzma.decompress(tar.extractfile(member).read())
                if hashlib.sha256(raw).hexdigest() != manifest.get(rel, {}).get("sha256"):
                    sys.exit(f"{shard}: {rel} does not match its SHA-256 in {manifest_path}: pack it again")
                chunks.setdefault(into / Path(rel).parent, {})[Path(rel).name] = raw
        for chunk, files in chunks.items():
            tmp = chunk.parent / f".{chunk.name}.carry-tmp"
            shutil.rmtree(tmp, ignore_errors=True)
            tmp.mkdir(parents=True)
            for name, raw in files.items():
                (tmp / name).write_bytes(raw)
            shutil.rmtree(chunk, ignore_errors=True)
            os.replace(tmp, chunk)
        print(f"{shard}: {len(chunks)} chunk(s) into {into}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="verb", required=True)
    p = sub.add_parser("pack")
    p.add_argument("stores", nargs="+", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--drop", nargs="*", default=[])
    p.add_argument("--shard-mib", type=float, default=30.0)
    p.add_argument("--preset", type=int, default=6)
    p.add_argument("--workers", type=int, default=2)
    u = sub.add_parser("unpack")
    u.add_argument("shards", nargs="+", type=Path)
    u.add_argument("--into", type=Path, default=Path("."))
    u.add_argument("--manifest", type=Path, default=None)
    a = parser.parse_args()
    if a.verb == "pack":
        pack(a.stores, a.out, a.drop, a.shard_mib, a.preset, a.workers)
    else:
        unpack(a.shards, a.into, a.manifest)


if __name__ == "__main__":
    main()
