"""Rollouts on Ray against the local backend: episodes/s end to end (start-up included) of the same plan.

    python benchmarks/ray_rollouts.py --dataset data/mqa [--per-level 20] [--address host:port]

Four runs of the random policy over the test split's COUNTING questions (``--per-level`` per level, one rollout
each, no depth or object maps stored): the local backend with 1 worker (in this process) and with 2 worker
processes, Ray with 2 actors on a local Ray, and Ray on a real two-node cluster of one CPU per node started on
this machine's loopback (``ray start`` twice; or the cluster at ``--address``). Every run's records are checked
bit-identical to the first run's.

Goals: 2 nodes x 1 CPU >= 1.7 x the local backend with 1 worker; the Ray backend's overhead against
the local pool at equal workers <= 15 %.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import tempfile
import time
from pathlib import Path

from mqa_rl.collectors.ray_pool import LOOPBACK_ENV

os.environ.update(LOOPBACK_ENV)          # before torchrl imports Ray

import torch  # noqa: E402

from mqa_rl import keys  # noqa: E402
from mqa_rl.collectors.ray_pool import loopback_cluster  # noqa: E402
from mqa_rl.collectors.rollouts import collect_rollouts  # noqa: E402
from mqa_rl.collectors.store import load_records  # noqa: E402


def same_records(a_root: Path, b_root: Path) -> bool:
    a, b = load_records(a_root), load_records(b_root)
    a, b = a[a[keys.SLOT].argsort()], b[b[keys.SLOT].argsort()]
    return a.shape == b.shape and all(
        torch.equal(torch.nan_to_num(a.get(k)), torch.nan_to_num(b.get(k))) if a.get(k).is_floating_point()
        else torch.equal(a.get(k), b.get(k)) for k in a.keys(True, True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dataset", default="data/mqa")
    parser.add_argument("--per-level", type=int, default=20)
    parser.add_argument("--address", default=None, help="an existing cluster's host:port (default: start a loopback one)")
    args = parser.parse_args()
    plan = dict(dataset=args.dataset, policy={"kind": "random"}, split="test", question_types=["counting"],
                max_per_group=args.per_level, repeats=1, store_depth=False, store_object_map=False, progress=False)
    runs = [("local, 1 worker", dict(workers=1)), ("local, 2 workers", dict(workers=2)),
            ("ray (local Ray), 2 actors", dict(workers=2, backend="ray")),
            ("ray, 2 nodes x 1 CPU", dict(workers=2, backend="ray", ray_address="cluster"))]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, options) in enumerate(runs):
            out = Path(tmp) / str(i)
            with (loopback_cluster(2, 1) if options.get("ray_address") == "cluster" and not args.address
                  else contextlib.nullcontext(args.address)) as address:
                if options.get("ray_address") == "cluster":
                    options = {**options, "ray_address": address}
                t0 = time.perf_counter()
                summary = collect_rollouts(out, **plan, **options)
                seconds = time.perf_counter() - t0
            identical = same_records(Path(tmp) / "0", out)
            rows.append((name, summary["episodes"], seconds, summary["episodes"] / seconds, identical))
            print(f"{name}: {summary['episodes']} episodes in {seconds:.1f} s ({rows[-1][3]:.3f}/s), "
                  f"identical to the first: {identical}", flush=True)
    base = rows[0][3]
    print("\n| run | episodes | seconds | episodes/s | x local 1 worker | bit-identical |\n|---|---|---|---|---|---|")
    for name, n, seconds, rate, identical in rows:
        print(f"| {name} | {n} | {seconds:.1f} | {rate:.3f} | {rate / base:.2f} | {identical} |")
    print(f"\n2 nodes x 1 CPU vs local 1 worker: {rows[3][3] / base:.2f}x (goal >= 1.7)")
    print(f"Ray overhead at 2 workers: local Ray {1 - rows[2][3] / rows[1][3]:+.1%}, "
          f"two nodes {1 - rows[3][3] / rows[1][3]:+.1%} of the local pool's rate (goal <= 15 %)")


if __name__ == "__main__":
    main()
