"""Episodes past one machine: a pool of Ray actors with ``multiprocessing.Pool``'s interface.

    with ray_session(address="auto"):          # join a cluster (``auto`` or ``host:port``); None: a local Ray
        pool = RayPool(workers=4, initializer=build, initargs=(...,))
        for result in pool.imap_unordered(fn, tasks):
            ...
        pool.terminate()

Each actor runs ``initializer(*initargs)`` once (it builds its env and policy) and then ``fn(task)`` for
the tasks it is handed, one at a time, in a process whose module globals hold what the initializer built,
as a pool worker's do. The pool starts no more actors than the cluster has CPUs free for, and the driver keeps
two tasks in flight per running actor (one running, one queued, so an actor never waits for the driver; none on
an actor not placed yet) and hands the next one to whichever actor finishes first, so a slow node takes
fewer. A task whose actor dies (its process killed, its node lost) is handed to another actor, and a new actor replaces the dead one (up to ``max_replacements``): the
caller, which alone writes results, sees every task's result exactly once, so nothing is lost or
duplicated. The actors are the TorchRL-free half of the Ray backend; DQN training uses TorchRL's own
``RayCollector`` (``mqa_rl.collectors.factory``).
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import tempfile
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

BACKENDS = ("local", "ray")
RAY_EXTRA = ("the Ray backend needs the 'ray' extra: pip install -e '.[ray]' (tools/bootstrap.sh installs it "
             "with the pinned packages); or choose backend=local")
REPO_ROOT = str(Path(__file__).resolve().parents[2])


def check_backend(backend: str, what: str = "backend", workers: int | None = None,
                  workers_what: str = "workers") -> str:
    """``backend``, or a ValueError listing the choices; with ``workers``, also one when the Ray backend would get
    no actor (a local Ray of 0 CPUs places none: it would wait forever), before anything is written."""
    if backend not in BACKENDS:
        raise ValueError(f"{what}={backend!r}: choose one of {list(BACKENDS)} (local: processes on this machine; "
                         "ray: actors on a Ray cluster, ray.address=auto or host:port joins one)")
    if backend == "ray" and workers is not None:
        check_workers(workers, workers_what)
    return backend


def check_workers(workers: int, what: str = "workers") -> int:
    """``workers`` for the Ray backend: at least one actor (one CPU each; a local Ray gets that many CPUs)."""
    if int(workers) < 1:
        raise ValueError(f"{what}={workers}: the Ray backend runs one actor of one CPU per worker, so it needs "
                         f"{what} ≥ 1 (a local Ray started with {workers} CPUs would never place one)")
    return int(workers)


def import_ray():
    """``ray``, or an ImportError that names the extra to install."""
    try:
        import ray
    except ImportError as error:
        raise ImportError(RAY_EXTRA) from error
    return ray


def ray_init_options(address: str | None = None, num_cpus: int | None = None) -> dict:
    """``ray.init`` keywords: join the cluster at ``address`` (``auto``: the one ``ray start`` made on this
    machine; ``host:port``), or start a local Ray with ``num_cpus`` when None. Workers import this checkout
    (``PYTHONPATH``) with one OpenMP thread each (one CPU per actor)."""
    path = os.pathsep.join(p for p in (REPO_ROOT, os.environ.get("PYTHONPATH", "")) if p)
    options = dict(include_dashboard=False, log_to_driver=False, configure_logging=False,
                   runtime_env={"env_vars": {"PYTHONPATH": path, "OMP_NUM_THREADS": "1"}})
    # "local": a new Ray for this run, even where `ray start` left a cluster on this machine
    return {**options, "address": address} if address else {**options, "address": "local", "num_cpus": num_cpus}


@contextlib.contextmanager
def ray_session(address: str | None = None, num_cpus: int | None = None):
    """Ray for the block (``ray_init_options``); shuts down only what it started."""
    ray = import_ray()
    if ray.is_initialized():
        yield ray
        return
    if not address and num_cpus is not None:
        check_workers(num_cpus)
    check_ray_address(address)                  # where Ray itself would retry for minutes
    try:
        ray.init(**ray_init_options(address, num_cpus))
    except ConnectionError as error:
        raise ConnectionError(f"no Ray cluster at ray.address={address!r}, or it refused this driver: {HINT}") from error
    try:
        yield ray
    finally:
        ray.shutdown()


def _died(ray) -> tuple[type, ...]:
    """The errors that mean a task's actor (or its node) is gone, not that the task failed."""
    names = ("RayActorError", "WorkerCrashedError", "NodeDiedError", "ActorDiedError")
    return tuple(getattr(ray.exceptions, n) for n in names if hasattr(ray.exceptions, n))


class _Worker:
    def __init__(self, initializer: Callable | None, initargs: tuple):
        if initializer is not None:
            initializer(*initargs)

    def run(self, fn: Callable, task):
        return fn(task)


def _listening(address: str, timeout: float = 5.0) -> bool:
    host, _, port = address.rpartition(":")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            return True
    except (OSError, ValueError):
        return False


HINT = ("ray.address is the address `ray start --head` printed (its GCS port, 6379 by default; not the dashboard's "
        "8265 nor a worker node's port): start a head there (ray start --head), or leave ray.address unset for a "
        "local Ray; a cluster with token authentication needs RAY_AUTH_MODE=token here and its ~/.ray/auth_token")


def check_ray_address(address: str | None, timeout: float = 5.0) -> None:
    """Fail within seconds, saying what to do, where ``ray.init(address=...)`` would retry for minutes (the GCS
    client reconnects ~20 times for ~40 s each): nothing listens there, something that is not a Ray head does
    (the dashboard's port, a worker node's), or a head that refuses this driver's token. It asks the head's GCS
    for its cluster id, as ``ray.init`` does first, at the address ``ray.init`` would use (``auto`` resolved as Ray
    resolves it). None or "local" (a local Ray) passes; a Ray Client address (``ray://``) is only checked to listen."""
    if not address or address == "local":
        return
    import_ray()
    if address.startswith("ray://"):
        if not _listening(address.removeprefix("ray://")):
            raise ConnectionError(f"nothing listens at ray.address={address!r}: start the head's Ray Client server, "
                                  f"or {HINT}")
        return
    from ray._private import services

    try:
        target = services.canonicalize_bootstrap_address(address)
    except ConnectionError as error:        # auto with no cluster on this machine
        raise ConnectionError(f"ray.address={address!r}: {error} {HINT}") from None
    except ValueError as error:
        raise ValueError(f"ray.address={address!r} is no address ({error}): host:port, auto, or unset") from None
    shown = repr(address) if target == address else f"{address!r} ({target})"
    if not _listening(target, timeout):
        raise ConnectionError(f"nothing listens at ray.address={shown}: {HINT}")
    import grpc
    from ray._private.grpc_utils import init_grpc_channel
    from ray.core.generated import gcs_service_pb2, gcs_service_pb2_grpc

    channel = init_grpc_channel(target)
    try:
        gcs_service_pb2_grpc.NodeInfoGcsServiceStub(channel).GetClusterId(gcs_service_pb2.GetClusterIdRequest(),
                                                                          timeout=timeout)
    except grpc.RpcError as error:
        code = error.code()
        if code == grpc.StatusCode.UNAUTHENTICATED:
            raise ConnectionError(f"the Ray head at ray.address={shown} refuses this driver's credentials "
                                  f"({error.details()}): set RAY_AUTH_MODE=token here and copy the cluster's "
                                  "~/.ray/auth_token (or RAY_AUTH_TOKEN)") from None
        raise ConnectionError(f"something listens at ray.address={shown} but does not answer as a Ray head's GCS "
                              f"({code.name}: {(error.details() or '')[:200]}): {HINT}") from None
    finally:
        channel.close()


# Ray 2.60 authenticates with a token (~/.ray/auth_token, made by the first head): the nodes and the driver must
# agree on the mode, which Ray reads once, when first imported (torchrl imports it): set it before that.
LOOPBACK_ENV = {"RAY_AUTH_MODE": "token", "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "1"}   # 2nd: two nodes, one machine


@contextlib.contextmanager
def loopback_cluster(nodes: int = 2, cpus_per_node: int = 1):
    """A real ``nodes``-node Ray cluster on this machine's loopback for the block (tests, benchmarks): a head
    and ``nodes - 1`` more ``ray start`` nodes of ``cpus_per_node`` CPUs, as on a real cluster; yields its
    address (host:port); at the end its processes are stopped (those of this cluster only)."""
    os.environ.update(LOOPBACK_ENV)
    ray_cli = str(Path(sys.executable).with_name("ray"))
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"127.0.0.1:{port}"
    common = ("--node-ip-address=127.0.0.1", f"--num-cpus={cpus_per_node}", "--disable-usage-stats")
    session = None

    def ray_cli_run(*args):
        done = subprocess.run([ray_cli, *args], env=dict(os.environ), timeout=120, capture_output=True, text=True)
        if done.returncode:
            raise RuntimeError(f"`ray {' '.join(args)}` failed: {done.stderr[-1500:]}")

    try:
        ray_cli_run("get-auth-token", "--generate")       # a fresh machine has no token yet
        ray_cli_run("start", "--head", f"--port={port}", "--include-dashboard=false", *common)
        for _ in range(nodes - 1):
            ray_cli_run("start", f"--address={address}", *common)
        with ray_session(address) as ray:             # wait until every node has joined
            session = ray._private.worker.global_worker.node.get_session_dir_path()
            deadline = time.time() + 60
            while sum(n["Alive"] for n in ray.nodes()) < nodes and time.time() < deadline:
                time.sleep(0.5)
            if ray.cluster_resources().get("CPU") != nodes * cpus_per_node:
                raise RuntimeError(f"the loopback cluster has {ray.cluster_resources()} after 60 s, "
                                   f"not {nodes} nodes of {cpus_per_node} CPU")
        yield address
    finally:
        _stop_session(session)
        current = Path(tempfile.gettempdir()) / "ray" / "ray_current_cluster"     # `ray start` notes its head here
        with contextlib.suppress(OSError):
            if current.read_text().strip().endswith(f":{port}"):
                current.unlink()


def _stop_session(session: str | None) -> None:
    """End the processes of one Ray session (its daemons name the session's folder; its workers end with their
    raylet), not every Ray of this machine as ``ray stop`` would: another run's local Ray keeps going."""
    if session is None:
        return
    pids = []
    for proc in Path("/proc").iterdir():
        try:
            if proc.name.isdigit() and session in (proc / "cmdline").read_bytes().decode(errors="ignore"):
                pids.append(int(proc.name))
        except OSError:
            continue
    for sig in (15, 9):
        for pid in pids:
            with contextlib.suppress(OSError):
                os.kill(pid, sig)
        deadline = time.time() + 10
        while sig == 15 and time.time() < deadline and any(Path(f"/proc/{p}").exists() for p in pids):
            time.sleep(0.2)


class RayPool:
    """``workers`` Ray actors (``cpus_per_worker`` CPUs each) with ``imap_unordered``; see the module docstring.

    An actor the cluster cannot place yet (its CPUs taken) would hold the tasks queued on it forever, so the pool
    starts no more actors than the cluster has CPUs free for, and hands tasks only to actors that run (placed and
    initialised); each says so in a printed line when it changes the plan."""

    def __init__(self, workers: int, initializer: Callable | None = None, initargs: tuple = (), *,
                 cpus_per_worker: float = 1.0, max_replacements: int | None = None, tasks_per_worker: int = 2,
                 free_wait_s: float = 3.0):
        ray = import_ray()
        if not ray.is_initialized():
            raise RuntimeError("RayPool needs Ray up: use it inside `with ray_session(...)`")
        if workers < 1:
            raise ValueError(f"workers={workers}: need at least one Ray actor")
        self._ray = ray
        self._cpus = float(cpus_per_worker)
        free = self._free_slots(workers, free_wait_s)
        if free < 1:
            raise RuntimeError(f"the Ray cluster has no CPU free for an actor of {cpus_per_worker:g} CPU "
                               f"({ray.cluster_resources().get('CPU', 0):g} CPUs, all taken): wait for its other "
                               "jobs, add a node, or use backend=local")
        if workers > free:
            print(f"RayPool: {workers} actors asked for, the Ray cluster has CPUs free for {free}: starting {free}",
                  flush=True)
            workers = free
        self._cls = ray.remote(num_cpus=cpus_per_worker, max_restarts=0)(_Worker)
        self._init = (initializer, initargs)
        self.per_actor = max(1, int(tasks_per_worker))
        self.replacements_left = workers if max_replacements is None else int(max_replacements)
        self._starting: dict = {}                   # readiness ref -> actor not yet running (unplaced, initialising)
        self.running: list = []                     # actors placed and initialised: the only ones given tasks
        self.actors = [self._spawn() for _ in range(workers)]
        self.deaths = 0

    def _free_slots(self, wanted: int, wait_s: float) -> int:
        """Actors the cluster has CPUs free for now (a pool just terminated frees its CPUs within ~1 s: wait that)."""
        deadline = time.time() + wait_s
        while True:
            free = int(self._ray.available_resources().get("CPU", 0.0) / self._cpus + 1e-9)
            if free >= wanted or time.time() >= deadline:
                return free
            time.sleep(0.2)

    def _spawn(self):
        actor = self._cls.remote(*self._init)
        self._starting[actor.__ray_ready__.remote()] = actor
        return actor

    def _lost(self, actor, slots: list) -> list:
        """Forget a dead actor (and start its replacement while any are left); the slots without it."""
        if actor in self.actors:
            self.deaths += 1
            self.actors.remove(actor)
            if actor in self.running:
                self.running.remove(actor)
            if self.replacements_left > 0:
                self.replacements_left -= 1
                self.actors.append(self._spawn())
        return [a for a in slots if a is not actor]

    def _promote(self, refs: list, slots: list, error_box: list) -> list:
        """Actors whose readiness ``refs`` came back: running ones get task slots, dead ones are replaced."""
        for ref in refs:
            actor = self._starting.pop(ref)
            try:
                self._ray.get(ref)
            except _died(self._ray) as error:
                error_box[:] = [error]
                slots = self._lost(actor, slots)
                continue
            if actor in self.actors:
                self.running.append(actor)
                slots = slots + [actor] * self.per_actor
        return slots

    def imap_unordered(self, fn: Callable, tasks: Iterable, chunksize: int = 1, wait_note_s: float = 60.0) -> Iterator:
        ray = self._ray
        queue = deque(tasks)
        in_flight: dict = {}                        # object ref -> (actor, task)
        # two tasks per running actor: the next one waits in the actor's queue while the driver takes in a result
        slots = [a for a in self.running for _ in range(self.per_actor)]
        last_error: list = []
        waiting_since = time.time()
        while queue or in_flight:
            if self._starting:                       # every actor that has started running since the last pass
                done, _ = ray.wait(list(self._starting), num_returns=len(self._starting), timeout=0)
                slots = self._promote(done, slots, last_error)
            if not self.actors:
                raise RuntimeError(f"every Ray worker died ({self.deaths}); the last error: "
                                   f"{last_error[0] if last_error else '?'}")
            while queue and slots:
                actor = slots.pop()
                task = queue.popleft()
                in_flight[actor.run.remote(fn, task)] = (actor, task)
            ready, _ = ray.wait([*in_flight, *self._starting], num_returns=1, timeout=wait_note_s)
            if not ready:
                if not in_flight:
                    print(f"RayPool: no actor running after {time.time() - waiting_since:.0f} s "
                          f"({len(self._starting)} waiting for a CPU or still initialising; the cluster has "
                          f"{ray.available_resources().get('CPU', 0):g} CPUs free)", flush=True)
                continue
            if ready[0] in self._starting:
                slots = self._promote(ready, slots, last_error)
                continue
            actor, task = in_flight.pop(ready[0])
            try:
                result = ray.get(ready[0])
            except _died(ray) as error:
                queue.appendleft(task)               # run again elsewhere: its result was never delivered
                last_error[:] = [error]
                slots = self._lost(actor, slots)     # the first of its tasks to report the death counts it
                continue
            slots.append(actor)
            waiting_since = time.time()
            yield result
        if self._starting:
            print(f"RayPool: {len(self._starting)} of {len(self.actors)} actors not running (no CPU free for them on "
                  "the Ray cluster, or still starting): the running ones ran every task", flush=True)

    def terminate(self) -> None:
        for actor in self.actors:
            with contextlib.suppress(Exception):
                self._ray.kill(actor)
        self.actors, self.running, self._starting = [], [], {}

    def join(self) -> None:
        pass
