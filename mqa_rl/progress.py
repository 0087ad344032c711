"""Progress of long work: a tqdm bar with rate and ETA on a terminal, and a one-line status every
``every_s`` seconds when the output goes to a file (a log a user tails shows the job alive and its ETA)."""

from __future__ import annotations

import sys
import time
from typing import Iterable, Iterator, TypeVar

T = TypeVar("T")


def _clock(seconds: float) -> str:
    seconds = int(max(seconds, 0))
    return f"{seconds // 3600}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}" if seconds >= 3600 \
        else f"{seconds // 60}:{seconds % 60:02d}"


def status_line(desc: str, done: int, total: int | None, elapsed: float, unit: str, rate_from: int = 0,
                postfix: str = "") -> str:
    """``desc: 12/100 scene, 0.41 scene/s, 0:29 elapsed, ETA 3:34`` (no rate or ETA before the first item; the
    rate counts from ``rate_from``, e.g. where a resumed run started)."""
    line = f"{desc}: {done}/{total if total is not None else '?'} {unit}, "
    counted = done - rate_from
    if counted > 0 and elapsed > 0:
        rate = counted / elapsed
        line += f"{rate:.3g} {unit}/s, {_clock(elapsed)} elapsed"
        if total is not None:
            line += f", ETA {_clock((total - done) / rate)}"
    else:
        line += f"{_clock(elapsed)} elapsed"
    return line + (f", {postfix}" if postfix else "")


class Progress:
    """``update(n)`` / ``set_postfix(**values)`` / ``close()`` as tqdm's, for a loop that counts by hand."""

    def __init__(self, total: int | None = None, desc: str = "", unit: str = "it", initial: int = 0,
                 every_s: float = 30.0, stream=None, disable: bool = False):
        self.stream = stream if stream is not None else sys.stderr
        self.total, self.desc, self.unit, self.every_s = total, desc, unit, every_s
        self.done = self.initial = initial
        self.disable, self.postfix = disable, ""
        self.start = self.last = time.perf_counter()
        self.bar = None
        if not disable and getattr(self.stream, "isatty", lambda: False)():
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=initial, desc=desc, unit=unit, dynamic_ncols=True, file=self.stream)

    def update(self, n: int = 1) -> None:
        self.done += n
        if self.bar is not None:
            self.bar.update(n)
            return
        now = time.perf_counter()
        if not self.disable and now - self.last >= self.every_s:
            self._print(now)
            self.last = now

    def set_postfix(self, **values) -> None:
        if self.bar is not None:
            self.bar.set_postfix(**values)
        self.postfix = ", ".join(f"{k} {v}" for k, v in values.items())

    def _print(self, now: float, end: str = "") -> None:
        print(status_line(self.desc, self.done, self.total, now - self.start, self.unit, self.initial, self.postfix)
              + end, file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        elif not self.disable:
            self._print(time.perf_counter(), " (done)")


def progress(iterable: Iterable[T], total: int | None = None, desc: str = "", unit: str = "it",
             every_s: float = 30.0, stream=None) -> Iterator[T]:
    """Iterate ``iterable``, showing its progress: a bar on a terminal, a status line every ``every_s`` s
    (and at the end) otherwise."""
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)
    shown = Progress(total, desc, unit, every_s=every_s, stream=stream)
    for item in iterable:
        yield item
        shown.update()
    shown.close()
