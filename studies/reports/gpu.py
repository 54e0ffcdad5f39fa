"""The GPU path, measured: the bench on a CUDA device beside the same figures on this project's CPU, and one short
real run (Diffuser's preset trained on medium on the GPU, evaluated).

Rows, all under docs/results/gpu/ (its README says how each was made): ``bench.json``, the GPU's
``bridgeplan bench`` (``scripts/gpu-check.sh``); ``cpu*/bench.json``, the CPU's at the same settings (merged: a
figure taken by several is read from the first in name order); ``eval-*.json``, the real run's evaluations.
Diffuser's published seconds per plan (:data:`DIFFUSER_SECONDS`) stand beside them with their hardware.

Made by `bridgeplan study report gpu` (studies/gpu.toml) into docs/results/gpu.md and the README's block.
"""

from __future__ import annotations

import json
from pathlib import Path

from bridgeplan.analysis.tables import table
from bridgeplan.errors import BridgeplanError

READS = ()
"""No study's trained methods: the rows are the bench's and the run's own JSONs."""
FOLDER = "gpu"
DIFFUSER_SECONDS = {"umaze": 1.1, "medium": 9.9, "large": 9.9}
"""Seconds per Diffuser plan at its own settings (umaze H = 128, T = 64; medium and large T = 256) on one RTX 8000,
as a later paper timed them (Hierarchical Diffuser, Chen et al. 2024: ../shared/REFERENCE.md)."""


def _read(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise BridgeplanError(f"cannot read {path}: {e}") from None


def load(root: Path) -> tuple[dict, list[dict], dict[str, dict]]:
    """(the GPU bench, the CPU benches in name order, the real run's evaluations by file stem)."""
    folder = Path(root) / FOLDER
    gpu = _read(folder / "bench.json")
    cpus = [_read(p) for p in sorted(folder.glob("cpu*/bench.json"))]
    evals = {p.stem: _read(p) for p in sorted(folder.glob("eval-*.json"))}
    return gpu, cpus, evals


def _latency_key(r: dict) -> tuple:
    return r["preset"], r["method"], r["batch"], r["nfe"]


def _throughput_key(r: dict) -> tuple:
    return r["preset"], r["maze"], r["batch"], r["precision"], r["implementation"]


def _first(rows_by_bench: list[list[dict]], key) -> dict:
    out: dict = {}
    for rows in rows_by_bench:
        for r in rows:
            out.setdefault(key(r), r)
    return out


def _quiet(rows: list[dict]) -> list[dict]:
    """A CPU bench's throughput rows on a quiet machine at one thread (it also times busy cores and more threads)."""
    return [r for r in rows if r["busy_cores"] == 0 and r["threads"] == 1]


def latency_table(gpu: dict, cpus: list[dict]) -> list[str]:
    cpu = _first([c["latency"] for c in cpus], _latency_key)
    body = []
    for r in gpu["latency"]:
        c = cpu.get(_latency_key(r))
        body.append([r["preset"], r["method"], r["batch"], r["nfe"], f"{r['plan_ms']:.2f}",
                     f"{c['plan_ms']:.1f}" if c else "not timed",
                     _ratio(c["plan_ms"] / r["plan_ms"]) if c else ""])
    return table(["preset", "method", "batch", "NFE", "GPU ms / plan call", "CPU ms / plan call", "GPU speed-up"],
                 body)


def _ratio(x: float) -> str:
    return f"{x:.0f}x" if x >= 10 else f"{x:.1f}x"


def matmul_limits(bench: dict) -> dict[str, float]:
    """The bench's matmul GFLOP/s per precision (one thread count: a GPU's)."""
    return {r["precision"]: r["limit_gflops"]["matmul"] for r in bench.get("throughput", [])}


def throughput_table(gpu: dict, cpus: list[dict]) -> list[str]:
    cpu = _first([_quiet(c.get("throughput", [])) for c in cpus], _throughput_key)
    bf16 = matmul_limits(gpu).get("bf16")
    body = []
    for r in gpu["throughput"]:
        c = cpu.get(_throughput_key(r))
        body.append([r["preset"], f"{r['maze']} {r['horizon']} x {r['stride']}", f"{r['batch']} x {r['grad_accum']}",
                     r["precision"], r["implementation"], f"{r['step_ms']:.1f}", f"{r['windows_per_s']:,.0f}",
                     f"{r['gflops'] / 1000:.1f}", f"{r['gflops'] / bf16:.3f}" if bf16 else "",
                     f"{c['windows_per_s']:,.0f}" if c else "not timed"])
    return table(["preset", "maze, plan shape", "batch x accumulated", "precision", "implementation", "GPU step ms",
                  "GPU windows/s", "GPU TFLOP/s", "of the bf16 matmul", "CPU windows/s (1 thread)"], body)


def scored(evals: dict[str, dict]) -> list[dict]:
    """The evaluations that score the run: all its episodes planned in one batch (the batch-1 one only times a plan)."""
    return sorted((e for e in evals.values() if e["batch_size"] == e["episodes"]), key=lambda e: e["nfe"])


def run_lines(evals: dict[str, dict]) -> list[str]:
    """The real run's evaluations: its training (steps, minutes, windows/s in the real loop) and scores."""
    if not evals:
        return ["No real run committed."]
    first = next(iter(evals.values()))
    config = first["config"]
    windows = first["step"] * config["batch_size"] * config["grad_accum"]
    lines = [f"`{config['preset']}` preset on {first['maze']} ({config['horizon']} x {config['stride']} plans, "
             f"{first['diffusion_steps']} diffusion steps, batch {config['batch_size']} x {config['grad_accum']}, "
             f"{config['precision']}), trained for {first['train_seconds'] / 60:.1f} minutes on the GPU: "
             f"{first['step']:,} steps, {windows / first['train_seconds']:,.0f} windows/s in the training loop "
             f"(data `{config['dataset']}`).", ""]
    body = [[e["nfe"], e["episodes"], f"{e['score']['minari']['mean']:.1f} ± {e['score']['minari']['se']:.1f}",
             f"{e['success_rate']['mean']:.2f}", f"{e['plan_ms_per_plan']:.1f}",
             f"{e['floor_line']['score']['minari']['mean']:.1f}"] for e in scored(evals)]
    return lines + table(["NFE", "episodes (planned in one batch)", "score (Minari, mean ± SE over episodes)",
                          "success", "ms per plan", "the straight line alone"], body)


def diffuser_line(gpu: dict, evals: dict[str, dict]) -> str:
    """This GPU's time per plan at Diffuser's own settings beside Diffuser's published seconds."""
    umaze = next((r for r in gpu["latency"] if r["preset"] == "diffuser" and r["batch"] == 1 and r["nfe"] == 64
                  and r["method"].startswith("DDPM")), None)
    medium = next((e for e in evals.values() if e["batch_size"] == 1 and e["nfe"] == e["diffusion_steps"]), None)
    parts = []
    if umaze:
        parts.append(f"umaze's shape (128 states, NFE 64: Diffuser's T) {umaze['plan_ms']:.0f} ms against "
                     f"{DIFFUSER_SECONDS['umaze']} s")
    if medium:
        parts.append(f"the medium run ({medium['horizon']} states, NFE {medium['nfe']}) "
                     f"{medium['plan_ms_per_plan']:.0f} ms against {DIFFUSER_SECONDS['medium']} s")
    return ("One plan at batch 1 with Diffuser's network at Diffuser's settings: " + "; ".join(parts) +
            " (Diffuser published, one RTX 8000).") if parts else ""


def machine_line(bench: dict) -> str:
    m = bench["machine"]
    return m.get("gpu") or f"{m.get('cpu') or m['processor']}, {m['cpu_count']} cores"


def render(root: Path) -> str:
    gpu, cpus, evals = load(root)
    limits = matmul_limits(gpu)
    cpu_names = "; ".join(f"{machine_line(c)}, code {c['machine']['code_version']}" for c in cpus) or "none"
    lines = ["# The GPU path, measured", "",
             f"GPU: {machine_line(gpu)}, torch {gpu['machine']['torch']}, code {gpu['machine']['code_version']}. "
             f"CPU rows: {cpu_names} (one torch thread). How each file was made: "
             "[gpu/README.md](gpu/README.md); the GPU bench's own tables: [gpu/bench.md](gpu/bench.md).", "",
             "## Planning latency", "",
             "Milliseconds per plan call for the whole batch (untrained networks: time does not depend on the "
             f"weights), medians over {gpu['bench']['repeats']} calls after 2 warm-up calls.", ""]
    lines += latency_table(gpu, cpus)
    line = diffuser_line(gpu, evals)
    lines += ["", line] if line else []
    lines += ["", "## Training throughput", "",
              "`train.py`'s own step per preset, maze shape, batch and precision. The GPU's limit, measured in the "
              "same run (8192 x 8192 matmul): " + ", ".join(f"{p} {v / 1000:.0f} TFLOP/s" for p, v in limits.items()) +
              "; achieved TFLOP/s count the network's forward and backward passes only (torch's FLOP counter). CPU "
              "rows at one thread on a quiet core; the CPU times `diffuser`'s network at its own batch 32 only.", ""]
    lines += throughput_table(gpu, cpus)
    lines += ["", "## A real run on the GPU", ""] + run_lines(evals)
    return "\n".join(lines)


def block(root: Path) -> str:
    """The README's sentence on the device: what was measured on a GPU, and where."""
    gpu, _, evals = load(root)
    first = {b: next(r for r in gpu["latency"] if r["batch"] == b and r["nfe"] == 1)
             for b in (1, 1024) if any(r["batch"] == b and r["nfe"] == 1 for r in gpu["latency"])}
    parts = [f"Measured on one {machine_line(gpu)} ([docs/results/gpu.md](docs/results/gpu.md)): a plan at NFE 1 takes "
             + " and ".join(f"{r['plan_ms']:.1f} ms at batch {b}" for b, r in first.items())
             + f" ({next(iter(first.values()))['preset']}, {next(iter(first.values()))['method']})"]
    line = diffuser_line(gpu, evals)
    if gpu["throughput"]:
        best = max(gpu["throughput"], key=lambda r: r["gflops"])
        bf16 = matmul_limits(gpu).get("bf16")
        parts.append(f"training reaches {best['gflops'] / 1000:.1f} TFLOP/s at best ({best['preset']}, {best['maze']}, "
                     f"batch {best['batch']} x {best['grad_accum']}, {best['precision']}, {best['windows_per_s']:,.0f} "
                     "windows/s)" + (f", {best['gflops'] / bf16:.0%} of the bf16 matmul rate measured in the same "
                                     f"run ({bf16 / 1000:.0f} TFLOP/s)" if bf16 else ""))
    runs = scored(evals)
    if runs:
        parts.append(f"Diffuser's preset trained {runs[0]['train_seconds'] / 60:.1f} minutes there on medium scores "
                     + ", ".join(f"{e['score']['minari']['mean']:.1f} ± {e['score']['minari']['se']:.1f} at NFE "
                                 f"{e['nfe']}" for e in runs) + f" ({runs[0]['episodes']} episodes)")
    return "; ".join(parts) + "." + (f" {line}" if line else "")
