"""Device choice: CUDA when present, overridable with ``--device``; and the CPU a result was made on."""

from __future__ import annotations

from pathlib import Path

import torch

from bridgeplan.errors import BridgeplanError


def resolve_device(name: str = "auto") -> torch.device:
    """``auto`` picks CUDA if available, else CPU; a named device must exist."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except RuntimeError as e:
        raise BridgeplanError(f"unknown device {name!r}: {e}") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise BridgeplanError(f"device {name!r} asked for, but CUDA is not available on this machine")
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        raise BridgeplanError(f"device {name!r} asked for, but this machine has {torch.cuda.device_count()} "
                              "CUDA device(s)")
    if device.type == "mps" and not torch.backends.mps.is_available():
        raise BridgeplanError(f"device {name!r} asked for, but MPS is not available on this machine")
    return device


def configure_threads(requested: int = 0, device: torch.device | None = None) -> int:
    """Set torch's CPU threads and return the number set.

    ``0`` (the default everywhere) means one thread on a CPU device: the networks here are small,
    so a second thread buys little on a quiet machine, while with another busy process on the
    cores torch's default (one thread per core) made training ~16x slower (threads wait for each
    other at every small op). Pass ``--threads N`` to use more on a machine you have to yourself.
    More threads than cores only warns.
    """
    import os
    import warnings

    if requested < 0:
        raise BridgeplanError(f"threads must be >= 0, got {requested}")
    cores = os.cpu_count() or 1
    if requested > cores:
        warnings.warn(f"--threads {requested} is more than this machine's {cores} cores: expect slower runs",
                      stacklevel=2)
    threads = requested or (1 if device is None or device.type == "cpu" else min(4, cores))
    torch.set_num_threads(threads)
    return threads


CPU_EXTENSIONS = ("avx2", "avx512f", "avx512_bf16", "amx_bf16")
"""The CPU's vector extensions that decide training speed here: fp32 GEMMs (AVX2, AVX-512) and bf16 ones."""


def cpu_model(cpuinfo: str | None = None) -> str:
    """The CPU's model name and which of :data:`CPU_EXTENSIONS` it has (``AMD EPYC (avx2)``), from /proc/cpuinfo;
    '' where there is none (not Linux). The same code runs at very different speeds on two x86 CPUs: a figure needs its
    CPU."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text()
        except OSError:
            return ""
    fields = dict(line.split(":", 1) for line in cpuinfo.splitlines() if ":" in line)
    fields = {k.strip(): v.strip() for k, v in fields.items()}
    name, flags = fields.get("model name", ""), set(fields.get("flags", "").split())
    extensions = [f for f in CPU_EXTENSIONS if f in flags]
    return f"{name} ({', '.join(extensions)})" if name and extensions else name
