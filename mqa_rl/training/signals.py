"""SIGTERM as an exception in long-running recipes.

``kill <pid>`` then unwinds like Ctrl-C: ``finally`` blocks run, so collector workers shut down,
finished episodes are flushed and loggers close instead of the process dying mid-write.
"""

from __future__ import annotations

import signal


def _raise_exit(signum, frame):
    raise SystemExit(f"terminated by signal {signum}")


def exit_on_sigterm() -> None:
    """Turn SIGTERM into ``SystemExit`` in this process (call from a recipe's ``main``)."""
    signal.signal(signal.SIGTERM, _raise_exit)
