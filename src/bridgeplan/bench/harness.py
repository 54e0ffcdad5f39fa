"""Timing: medians after warm-up, interleaved ratios, and the machine the figures were taken on."""

from __future__ import annotations

import contextlib
import os
import platform
import statistics
import tempfile
import time

import torch

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


def median_seconds(fn, repeats: int, device: torch.device, warmup: int = 2) -> float:
    for _ in range(warmup):
        fn()
    return statistics.median(timed(fn, device) for _ in range(repeats))


def interleaved_ratios(fns: dict[str, object], base: str, rounds: int, device: torch.device) -> dict[str, float]:
    """Median time of each function over the median time of ``base``, timed in alternating rounds.

    Alternating keeps a slow patch of the machine (another process, a frequency change) from landing
    on one side of a ratio only. ``<base>_ms`` holds the base's median in milliseconds.
    """
    for fn in fns.values():
        fn()
        fn()
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(rounds):
        for name, fn in fns.items():
            times[name].append(timed(fn, device))
    base_s = statistics.median(times[base])
    return {name: statistics.median(t) / base_s for name, t in times.items() if name != base} | {
        f"{base}_ms": 1000 * base_s}


def machine(device: torch.device) -> dict:
    out = {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
           "cpu_count": os.cpu_count(), "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
           "device": str(device), "code_version": code_version()}
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


@contextlib.contextmanager
def busy_cores(n: int):
    """``n`` other processes spinning on the CPU (a laptop's browser, a second job of a sweep)."""
    import subprocess
    import sys

    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        time.sleep(0.5)  # let the scheduler see them
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()
