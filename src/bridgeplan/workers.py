"""Worker processes of the local pools (a study's seeds, a sweep's jobs, a dataset's streams) end with their parent;
:func:`run_spawned` runs calls in worker processes and names one that was killed instead of waiting for it;
:class:`Executor` runs a study's units of work (a grid's runs, declared evaluations' training seeds) one way for both:
in this process, in worker processes, or as Ray tasks.

A pool's workers are spawned processes of their own: when the command that started them is killed without the time
to stop its pool (SIGTERM from a scheduler, SIGKILL), they would train on as orphans, holding their runs' locks and
both cores, beside the command run next. Each worker watches its parent instead, and exits once it is gone."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess

from bridgeplan.errors import BridgeplanError, check_choice

PARENT_POLL_SECONDS = 1.0


def exit_with_parent(poll_seconds: float = PARENT_POLL_SECONDS) -> None:
    """A pool's initializer: a daemon thread that ends this process when its parent has gone (the parent id
    changes when the process is re-parented)."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_seconds)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


class WorkerDied(BridgeplanError):
    """A worker process ended without answering: killed (the kernel's out-of-memory killer sends SIGKILL)."""


_PARENT: Connection | None = None
"""In a worker of :func:`run_spawned`: where it tells its parent what it is doing (:func:`doing`)."""


def doing(what: str) -> None:
    """Tell the parent, where this process is a worker of :func:`run_spawned`, what it does now: named if it dies."""
    if _PARENT is not None:
        _PARENT.send(("doing", what))


def _worker(parent: Connection, call: Callable, args: tuple) -> None:
    global _PARENT
    from tqdm import tqdm

    exit_with_parent()
    _PARENT = parent
    # this process's bars need a lock of its own only: tqdm's default, a named semaphore, would outlive a killed worker
    # (the resource tracker's warning at exit)
    tqdm.set_lock(threading.RLock())
    try:
        answer = ("done", call(*args))
    except BaseException as e:  # raised again in the parent, as a pool's map does
        answer = ("raised", e)
    try:
        parent.send(answer)
    except Exception as e:  # an answer that does not pickle
        parent.send(("raised", RuntimeError(f"{type(answer[1]).__name__}: {answer[1]} (unpicklable: {e})")))


def run_spawned(call: Callable, arguments: list[tuple], workers: int, names: list[str], progress: bool = False) -> list:
    """``call(*args)`` for each ``args`` of ``arguments``, each in a spawned process of its own, at most ``workers``
    at once; their results in order. A process per call rather than a pool: a pool whose worker is killed loses its
    task and waits for it forever. A call that raises: its exception raised here once the others have ended. A process
    that ends without answering (killed): :class:`WorkerDied` naming it (``names[i]``) and what it last said it was
    doing (:func:`doing`), once the others have ended (what they finished is kept). ``progress``: a line on stderr
    whenever a worker says what it does and when it ends (the workers draw no bars: theirs would interleave)."""
    ctx = mp.get_context("spawn")
    waiting = list(range(len(arguments)))
    running: dict[Connection, tuple[int, BaseProcess]] = {}
    results: list = [None] * len(arguments)
    raised: list[BaseException] = []
    died: list[str] = []
    last: dict[int, str] = {}
    ended = 0
    while waiting or running:
        while waiting and len(running) < workers:
            i = waiting.pop(0)
            receive, send = ctx.Pipe(duplex=False)
            process = ctx.Process(target=_worker, args=(send, call, arguments[i]), daemon=True)
            process.start()
            send.close()  # the child's end: the parent's copy closed, EOF comes when the child ends
            running[receive] = (i, process)
        for conn in wait(list(running)):
            i, process = running[conn]
            try:
                kind, value = conn.recv()
            except EOFError:
                kind, value = "died", None
            if kind == "doing":
                last[i] = value
                _say(progress, f"{names[i]}: {value}")
                continue
            del running[conn]
            conn.close()
            process.join()
            ended += 1
            _say(progress, f"{names[i]}: {'done' if kind == 'done' else 'failed'} ({ended} of {len(arguments)} ended)")
            if kind == "done":
                results[i] = value
            elif kind == "raised":
                raised.append(value)
            else:
                died.append(f"{names[i]} {_death(process.exitcode)}"
                            + (f" while {last[i]}" if i in last else ""))
    if died:
        raise WorkerDied("; ".join(died))
    if raised:
        raise raised[0]
    return results


@dataclass(frozen=True)
class Unit:
    """A unit of a study's work: ``call(*args, threads, progress)`` (``threads``: its torch threads, 0 the run's own
    setting; ``progress``: whether it draws bars), named for the error that says it died. Its answer is how many rows
    or JSONs it wrote."""

    call: Callable
    args: tuple
    name: str


def _run_unit(unit: Unit, threads: int, progress: bool):
    return unit.call(*unit.args, threads, progress)


@dataclass(frozen=True)
class Executor:
    """How a study's units of work run (:class:`Unit`: a grid's trained run and its evaluations, a declared
    evaluation's training seed): one after another in this process (``workers`` 1), ``workers`` at once in spawned
    processes of their own (the cores divided among them), or as tasks of a Ray cluster (``ray``: the connected
    module, :func:`connect_ray`; one CPU each, and ``gpus`` of a GPU)."""

    workers: int = 1
    ray: object = None
    gpus: float = 0.0

    def map(self, units: list[Unit], progress: bool) -> list:
        """Every unit's answer, in order. A worker that dies: one error naming it, and that what the finished units
        wrote is kept."""
        if self.ray is not None:  # each task writes its own rows or JSONs: a cluster shares the results folder
            task = self.ray.remote(num_cpus=1, num_gpus=self.gpus)(_run_unit)
            return self.ray.get([task.remote(unit, 1, False) for unit in units])
        if self.workers == 1 or len(units) <= 1:
            return [_run_unit(unit, 0, progress) for unit in units]
        threads = max(1, (os.cpu_count() or 1) // self.workers)
        os.environ.setdefault("OMP_NUM_THREADS", str(threads))
        try:  # one unit per process: a worker never holds two while another idles
            return run_spawned(_run_unit, [(unit, threads, False) for unit in units], min(self.workers, len(units)),
                               [unit.name for unit in units], progress)
        except WorkerDied as e:
            raise BridgeplanError(f"{e}; what the others wrote is kept: the same command again runs what is "
                                  f"missing") from None


BACKENDS = ("local", "ray")


def check_backend(backend: str) -> None:
    check_choice("backend", backend, BACKENDS)


@contextmanager
def executor(backend: str = "local", workers: int = 1, ray_address: str | None = None,
             device: str = "auto") -> Iterator[Executor]:
    """The :class:`Executor` of ``backend``: ``local`` with ``workers``, or ``ray`` connected to ``ray_address`` (a
    local instance where None) for the while, its tasks each given a GPU where this machine has one and the runs'
    ``device`` is not ``cpu``. A cluster that does not answer fails here, before any work."""
    check_backend(backend)
    if workers < 1:
        raise BridgeplanError(f"workers must be >= 1, got {workers}")
    if backend == "local":
        yield Executor(workers)
        return
    import torch

    ray = connect_ray(ray_address)
    try:
        yield Executor(workers, ray, 1.0 if device != "cpu" and torch.cuda.is_available() else 0.0)
    finally:
        ray.shutdown()


def connect_ray(address: str | None):
    """Join the Ray cluster at ``address``, or start a local instance; returns the ``ray`` module. Its tasks write
    their rows into the shared results store (safe for concurrent writers) or their JSONs themselves, so on a cluster
    the results folder must be on a shared filesystem."""
    try:
        import ray
    except ImportError:
        raise BridgeplanError("the ray backend needs the extra: pip install 'bridgeplan[ray]'") from None
    if address:
        _check_reachable(address)
    try:
        if address:
            ray.init(address=address, ignore_reinit_error=True, log_to_driver=False)
        else:
            ray.init(ignore_reinit_error=True, log_to_driver=False, include_dashboard=False)
    except Exception as e:  # ray raises ConnectionError, RuntimeError, ValueError, its own types...
        raise BridgeplanError(f"cannot connect to Ray at {address or 'a local instance'}: "
                              f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}") from None
    return ray


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """Fail fast on a ``host:port`` that does not answer (``ray.init`` would retry for minutes)."""
    import socket

    target = address.removeprefix("ray://")
    host, sep, port = target.rpartition(":")
    if not sep or not port.isdigit():
        return  # "auto" or another form ray resolves itself
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout).close()
    except OSError as e:
        raise BridgeplanError(f"the Ray cluster at {address} does not answer: {e}") from None


def _say(progress: bool, line: str) -> None:
    if progress:
        print(f"[{time.strftime('%H:%M:%S')}] {line}", file=sys.stderr, flush=True)


def _death(exitcode: int | None) -> str:
    """How a process that never answered ended."""
    if exitcode is not None and exitcode < 0:
        name = signal.Signals(-exitcode).name
        return f"was killed by {name}" + (" (likely out of memory)" if -exitcode == signal.SIGKILL else "")
    return f"exited with code {exitcode} without an answer"
