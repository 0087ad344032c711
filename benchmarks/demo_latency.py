"""Web demo latency as a visitor sees it: time from "Run" to the first frame and between frames
(one per env step), with one and with two visitors running episodes at once, measured through the
page's HTTP API (gradio_client, which downloads each frame as a browser does) on a demo served by
this process on 127.0.0.1. Optionally a screenshot of the page after an episode (headless Chromium).

    python benchmarks/demo_latency.py --dataset data/mqa [--episodes 6] [--level hard]
    python benchmarks/demo_latency.py --runs checkpoints --policy 'learned stop' --screenshot docs/figures/demo_screenshot.png

The episodes use the random baseline (the number of pushes is random too) on the level's questions;
each visitor draws its own questions. "step" is the time between two successive frames, i.e. one
env step (physics, render, measurements, reward stack) plus the frame drawing and its transfer.
"""

from __future__ import annotations

import argparse
import logging
import random
import statistics
import tempfile
import threading
import time
from pathlib import Path

import torch
from omegaconf import OmegaConf

ROOT = Path(__file__).resolve().parents[1]
RANDOM = "random (paper's baseline)"


def episode_times(url: str, jobs: list[tuple[str, str]], seed: int) -> dict[str, list[float]]:
    """Run the episodes one after the other as one visitor; the arrival time of every update."""
    from gradio_client import Client

    client = Client(url, verbose=False, analytics_enabled=False, download_files=tempfile.mkdtemp(prefix="demo_bench_"))
    client.predict(jobs[0][0], "counting", api_name="/questions")     # connection open, as a loaded page's is
    first, steps, end, total = [], [], [], []
    for i, (scene_id, question_id) in enumerate(jobs):
        t0 = time.perf_counter()
        job = client.submit(scene_id, question_id, "", RANDOM, None, seed + i, api_name="/run")
        arrivals = [time.perf_counter() - t0 for _ in job]
        if "done after" not in job.outputs()[-1][5]:
            raise RuntimeError(f"episode failed: {job.outputs()[-1][5]}")
        first.append(arrivals[0])
        steps += [b - a for a, b in zip(arrivals[:-1], arrivals[1:])]
        total.append(arrivals[-1])
        end.append(arrivals[-1] - arrivals[-2] if len(arrivals) > 1 else float("nan"))
    return {"first": first, "step": steps, "total": total, "last": end}


def backend_times(backend, jobs: list[tuple[str, str]], seed: int) -> dict[str, list[float]]:
    """The same episodes called in this process without HTTP: the simulation's share of the latency."""
    first, steps = [], []
    for i, (scene_id, question_id) in enumerate(jobs):
        t0 = time.perf_counter()
        arrivals = [time.perf_counter() - t0 for _ in backend.run_episode(scene_id, question_id, "", RANDOM, None,
                                                                           seed + i, "benchmark")]
        first.append(arrivals[0])
        steps += [b - a for a, b in zip(arrivals[:-2], arrivals[1:-1])]       # the last one adds answer + video
    return {"first": first, "step": steps}


def summary(name: str, values: list[float]) -> str:
    values = sorted(values)
    p90 = values[min(len(values) - 1, int(round(0.9 * (len(values) - 1))))]
    return f"{name} median {statistics.median(values) * 1000:.0f} ms, p90 {p90 * 1000:.0f} ms (n={len(values)})"


def measure(url: str, backend, users: int, episodes: int, level: str, seed: int) -> None:
    rng = random.Random(seed)
    pool = [q for q in backend.dataset.select(difficulties=[level])]
    plans = [[(q.scene_id, q.id) for q in rng.sample(pool, episodes)] for _ in range(users)]
    results: list[dict] = [{} for _ in range(users)]
    threads = [threading.Thread(target=lambda k=k: results.__setitem__(k, episode_times(url, plans[k], seed + 100 * k)))
               for k in range(users)]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    wall = time.perf_counter() - t0
    merged = {key: [v for r in results for v in r[key]] for key in results[0]}
    print(f"{users} visitor(s), {episodes} {level} episodes each ({len(merged['step'])} frames after the first, "
          f"{wall:.1f} s wall):")
    print("  Run -> first frame: " + summary("", merged["first"]))
    print("  frame -> next frame (one env step): " + summary("", merged["step"]))
    print("  last step -> answer + video: " + summary("", [v for v in merged["last"] if v == v]))
    print("  whole episode: " + summary("", merged["total"]))
    if users == 1:
        direct = backend_times(backend, plans[0], seed)
        print("  of which the backend without HTTP: first frame " + summary("", direct["first"])
              + "; step " + summary("", direct["step"]))


def screenshot(url: str, backend, path: Path, level: str, policy: str | None) -> None:
    from mqa_rl.demo.page_driver import DemoPage, chromium

    driver = chromium(1400, 2500)
    try:
        page = DemoPage(driver, url)
        page.open()
        cards = backend.catalog.select()
        index = next(i for i, c in enumerate(cards) if c.difficulty == level)
        page.pick_scene(index)
        page.pick_question(0)
        trained = backend.policies.trained
        if trained:
            page.pick_policy(next((n for n in trained if policy in n), trained[0]) if policy else trained[0])
        shown = page.run()
        time.sleep(1.0)                                       # let the video player draw its first frame
        page.screenshot(path)
        print(f"screenshot {path}: {shown['message']}; {shown['answer'][:80]}")
    finally:
        driver.quit()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataset", default="data/mqa")
    ap.add_argument("--runs", default=None, help="folder of train_dqn runs (for the screenshot's policy)")
    ap.add_argument("--policy", default=None, help="the screenshot's policy: a part of its name in the page's list, "
                                                   "e.g. 'learned stop' (default: the first trained one)")
    ap.add_argument("--vqa", nargs="*", default=None, help="VQA checkpoints the page answers with (default: the demo's, "
                                                          "recipes/conf/demo.yaml)")
    ap.add_argument("--episodes", type=int, default=6, help="episodes per visitor")
    ap.add_argument("--level", default="hard", choices=["easy", "medium", "hard"])
    ap.add_argument("--max-pushes", type=int, default=10)
    ap.add_argument("--cache-dir", default=str(Path(tempfile.gettempdir()) / "mqa_demo_bench_cache"))
    ap.add_argument("--screenshot", type=Path, default=None, help="write a PNG of the page after an episode")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(1)

    from mqa_rl.demo.app import launch
    from mqa_rl.demo.backend import DemoBackend, DemoConfig

    reward = OmegaConf.to_container(OmegaConf.load(ROOT / "recipes" / "conf" / "reward" / "global_local.yaml"))
    vqa = args.vqa if args.vqa is not None else list(OmegaConf.load(ROOT / "recipes" / "conf" / "demo.yaml").vqa)
    t0 = time.perf_counter()
    backend = DemoBackend(DemoConfig(dataset=args.dataset, reward=reward, runs=args.runs, vqa=tuple(vqa), cache_dir=args.cache_dir,
                                     max_pushes=args.max_pushes, sessions=2))
    print(f"server start-up (dataset check, 2 simulators, shader compile, {len(backend.catalog.cards)} scene images, "
          f"{len(backend.policies.trained)} trained policies): {time.perf_counter() - t0:.1f} s")
    demo = launch(backend, port=None, block=False, quiet=True)
    url = demo.local_url
    try:
        episode_times(url, [(q.scene_id, q.id) for q in backend.dataset.select(difficulties=[args.level])[:1]], 0)  # warm-up
        for users in (1, 2):
            measure(url, backend, users, args.episodes, args.level, args.seed)
        if args.screenshot:
            screenshot(url, backend, args.screenshot, args.level, args.policy)
    finally:
        demo.close()
        backend.close()


if __name__ == "__main__":
    main()
