"""Time the default 100-scene dataset generation in 1 and 2 processes (scenes/s), check both give the same bytes, and
report its size on disk.

    python benchmarks/dataset_generation.py [--seed 0] [--workers 1 2] [--out /tmp/mqa_bench]

Run it on an idle machine: the 2-process figure is what `make_dataset.py` (workers=2) costs the main job.
"""

from __future__ import annotations

import argparse
import hashlib
import shutil
import tempfile
import time
from pathlib import Path

from mqa_rl.data import generate_dataset


def digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*")) if p.is_file()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="process counts to time")
    ap.add_argument("--out", type=Path, default=None, help="folder to write (default: a temporary one, removed)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp()) if args.out is None else None
    base = args.out if args.out is not None else tmp
    digests = {}
    for workers in args.workers:
        out = base / f"mqa_w{workers}"
        t0 = time.perf_counter()
        ds = generate_dataset(out, seed=args.seed, overwrite=True, progress=True, workers=workers)
        elapsed = time.perf_counter() - t0
        digests[workers] = digest(out)
        print(f"{workers} process(es): {elapsed:.1f} s for {len(ds.scenes)} scenes, {len(ds.scenes) / elapsed:.3f} scenes/s "
              f"({len(ds.questions)} questions); drop attempts {ds.manifest['drop_attempts']}", flush=True)
    if len(digests) > 1:
        same = len({tuple(d.items()) for d in digests.values()}) == 1
        print(f"same bytes for {', '.join(map(str, digests))} processes: {same}")
    out = base / f"mqa_w{args.workers[-1]}"
    files = [p for p in out.rglob("*") if p.is_file()]
    size = sum(p.stat().st_size for p in files)
    t1 = time.perf_counter()
    type(ds)(out)
    load = time.perf_counter() - t1
    print(f"size on disk: {size / 2**20:.1f} MiB in {len(files)} files "
          + ", ".join(f"{p.name} {p.stat().st_size / 2**20:.1f} MiB" for p in sorted(files, key=lambda p: -p.stat().st_size)[:3]))
    print(f"load + verify: {load:.2f} s")
    if tmp is not None:
        shutil.rmtree(tmp)


if __name__ == "__main__":
    main()
