"""Simulators shared by visitors: a fixed pool of envs, each lent to one episode at a time.

Two tabs never share an env during an episode: an episode borrows one for its whole run and gives it
back when it ends, fails, is stopped, or its page is closed (Gradio closes the episode's generator;
``borrow``'s ``finally`` returns the env). Every reset rebuilds the scene from stored poses, so what
the previous borrower did leaves no trace. The pool is built when the server starts: the shader
compile and the env construction are paid once, not per click.

``SessionFiles`` keeps each browser session's episode videos in its own folder (its last few only),
removed when the session ends (Gradio's unload hook).
"""

from __future__ import annotations

import queue
import re
import shutil
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path


class PoolBusy(RuntimeError):
    """Every env is running someone's episode."""


class EnvPool:
    def __init__(self, make_env: Callable[[], object], size: int):
        if size < 1:
            raise ValueError(f"the env pool needs at least 1 env, got {size}")
        self.size = size
        self._free: queue.Queue = queue.Queue()
        self._lock = threading.Lock()
        self.borrowers: dict[int, str] = {}             # id(env) -> session of the episode using it
        self.envs = [make_env() for _ in range(size)]
        for env in self.envs:
            self._free.put(env)

    @property
    def free(self) -> int:
        return self._free.qsize()

    @contextmanager
    def borrow(self, session: str, timeout: float = 30.0) -> Iterator[object]:
        try:
            env = self._free.get(timeout=timeout)
        except queue.Empty:
            raise PoolBusy(f"all {self.size} simulators are running other visitors' episodes; "
                           f"try again in a few seconds") from None
        with self._lock:
            self.borrowers[id(env)] = session
        try:
            yield env
        finally:
            with self._lock:
                self.borrowers.pop(id(env), None)
            self._free.put(env)

    def close(self) -> None:
        for env in self.envs:
            try:
                env.close()
            except Exception:                   # noqa: BLE001 - closing on shutdown, best effort
                pass


class SessionFiles:
    """One folder of files per browser session under ``root``."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def folder(self, session: str) -> Path:
        path = self.root / re.sub(r"[^A-Za-z0-9_-]", "_", session or "anonymous")[:64]
        path.mkdir(parents=True, exist_ok=True)
        return path

    def keep_last(self, session: str, n: int) -> None:
        """Remove all but the ``n`` newest files of the session (API clients never unload)."""
        files = sorted(self.folder(session).iterdir(), key=lambda f: f.stat().st_mtime_ns)
        for f in files[:-n] if n > 0 else files:
            f.unlink(missing_ok=True)

    def release(self, session: str) -> None:
        shutil.rmtree(self.folder(session), ignore_errors=True)
