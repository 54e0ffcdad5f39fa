"""Timing: medians after warm-up, interleaved ratios, and the machine the figures were taken on."""

from __future__ import annotations

import contextlib
import os
import platform
import statistics
import tempfile
import time

import torch

from bridgeplan.device import cpu_model
from bridgeplan.errors import BridgeplanError
from bridgeplan.files import code_version


def timed(fn, device: torch.device) -> float:
    """Wall seconds of one call of ``fn`` (the device synchronized before and after)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    t0 = time.perf_counter()
    fn()
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter() - t0


def interleaved_medians(fns: dict[str, object], rounds: int, device: torch.device, warmup: int = 2) -> dict[str, float]:
    """Median seconds of each function's call, timed in alternating rounds (one call of each per round) after
    ``warmup`` calls of each: a slow patch of the machine (another process, a frequency change) falls on every
    function alike, not on the one timed while it lasted."""
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(rounds):
        for name, fn in fns.items():
            times[name].append(timed(fn, device))
    return {name: statistics.median(t) for name, t in times.items()}


def interleaved_ratios(fns: dict[str, object], base: str, rounds: int, device: torch.device) -> dict[str, float]:
    """Median time of each function over the median time of ``base``, timed in alternating rounds
    (:func:`interleaved_medians`). ``<base>_ms`` holds the base's median in milliseconds."""
    medians = interleaved_medians(fns, rounds, device)
    base_s = medians[base]
    return {name: s / base_s for name, s in medians.items() if name != base} | {f"{base}_ms": 1000 * base_s}


def machine(device: torch.device) -> dict:
    out = {"platform": platform.platform(), "processor": platform.processor() or platform.machine(), "cpu": cpu_model(),
           "cpu_count": os.cpu_count(), "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
           "device": str(device), "code_version": code_version()}
    if hasattr(os, "getloadavg"):  # how busy the cores were: the figures are only as quiet as the machine
        out["load_1min_start"] = os.getloadavg()[0]
    if device.type == "cuda":
        out["gpu"] = torch.cuda.get_device_name(device)
    return out


@contextlib.contextmanager
def empty_inductor_cache():
    """Point inductor's on-disk cache at a fresh temporary directory, so a compile is timed cold."""
    previous = os.environ.get("TORCHINDUCTOR_CACHE_DIR")
    with tempfile.TemporaryDirectory(prefix="bridgeplan-inductor-") as cache_dir:
        os.environ["TORCHINDUCTOR_CACHE_DIR"] = cache_dir
        try:
            yield
        finally:
            if previous is None:
                del os.environ["TORCHINDUCTOR_CACHE_DIR"]
            else:
                os.environ["TORCHINDUCTOR_CACHE_DIR"] = previous


SPIN = "print('ready', flush=True)\nwhile True: pass"
"""Python source of a process that keeps one core busy and nothing else (a laptop's browser, say)."""


@contextlib.contextmanager
def busy_cores(n: int, code: str = SPIN):
    """``n`` other processes running Python ``code`` (by default spinning), yielded once each has printed a line
    to say it is ready (a training job after its warm-up step, say)."""
    import subprocess
    import sys

    env = os.environ | {"OMP_NUM_THREADS": "1"}  # each keeps to its own core
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, env=env)
             for _ in range(n)]
    try:
        for p in procs:
            if not p.stdout.readline():
                raise BridgeplanError(f"bench: the process meant to keep a core busy ended first: {code!r}")
        time.sleep(0.5)  # let the scheduler see them
        yield procs
    finally:
        for p in procs:
            p.kill()
            p.wait()


def running_only(procs, running) -> None:
    """Let the processes in ``running`` run and hold the other ``procs`` stopped (SIGSTOP / SIGCONT: POSIX)."""
    import signal

    for p in procs:
        p.send_signal(signal.SIGCONT if p in running else signal.SIGSTOP)
    time.sleep(0.2)  # let the scheduler see the change
