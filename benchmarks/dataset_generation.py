"""Time the default 100-scene dataset generation and report its size on disk.

    python benchmarks/dataset_generation.py [--seed 0] [--out /tmp/mqa_bench]

Goal: ≤ 5 minutes on a 2-core machine.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from mqa_rl.data import generate_dataset


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="folder to write (default: a temporary one, removed)")
    args = ap.parse_args()
    tmp = None
    out = args.out
    if out is None:
        tmp = Path(tempfile.mkdtemp())
        out = tmp / "mqa"
    t0 = time.perf_counter()
    ds = generate_dataset(out, seed=args.seed, overwrite=True, progress=True)
    elapsed = time.perf_counter() - t0
    files = [p for p in out.rglob("*") if p.is_file()]
    size = sum(p.stat().st_size for p in files)
    t1 = time.perf_counter()
    type(ds)(out)
    load = time.perf_counter() - t1
    print(f"generation: {elapsed:.1f} s for {len(ds.scenes)} scenes, {len(ds.questions)} questions "
          f"({elapsed / len(ds.scenes):.2f} s/scene); drop attempts {ds.manifest['drop_attempts']}")
    print(f"size on disk: {size / 2**20:.1f} MiB in {len(files)} files "
          + ", ".join(f"{p.name} {p.stat().st_size / 2**20:.1f} MiB" for p in sorted(files, key=lambda p: -p.stat().st_size)[:3]))
    print(f"load + verify: {load:.2f} s")
    if tmp is not None:
        shutil.rmtree(tmp)


if __name__ == "__main__":
    main()
