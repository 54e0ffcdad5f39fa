"""Benchmarks: planning latency, sampler overhead, training-step overhead, evaluation throughput.

Each figure is the median over repeats after warm-up; the machine is recorded beside it.
Not part of the tests: ``bridgeplan bench`` writes JSON and a Markdown table.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from bridgeplan.checkpoint import atomic_write_text, code_version
from bridgeplan.config import preset_config
from bridgeplan.data.normalizer import Normalizer
from bridgeplan.device import resolve_device
from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.prior_mlp import PriorMLP
from bridgeplan.planner import Planner
from bridgeplan.priors import make_prior
from bridgeplan.processes import DDPM, Bridge
from bridgeplan.trajectory import OBS_DIM, TRANSITION_DIM


def median_seconds(fn, repeats: int, warmup: int = 2, device: torch.device | None = None) -> float:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        if device is not None and device.type == "cuda":
            torch.cuda.synchronize(device)
        t0 = time.perf_counter()
        fn()
        if device is not None and device.type == "cuda":
            torch.cuda.synchronize(device)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def machine() -> dict:
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(), "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
            "code_version": code_version()}


def _normalizer() -> Normalizer:
    # umaze-like limits: actions in [-1, 1], positions in [-1.5, 1.5], velocities in [-5.3, 5.3]
    return Normalizer((-1, -1, -1.5, -1.5, -5.3, -5.3), (1, 1, 1.5, 1.5, 5.3, 5.3))


def _planners(model, horizon: int, device, steps: int) -> dict[str, Planner]:
    norm = _normalizer()
    learned = PriorMLP(OBS_DIM, horizon, TRANSITION_DIM).to(device).eval()
    out = {
        "ddpm (ancestral)": Planner(model, DDPM(steps), make_prior("gaussian", norm), norm, horizon, device),
        "ddpm (ddim)": Planner(model, DDPM(steps, sampler="ddim"), make_prior("gaussian", norm), norm, horizon, device),
    }
    for prior in ("gaussian", "line", "learned"):
        out[f"bridge ({prior})"] = Planner(model, Bridge(steps), make_prior(prior, norm, net=learned), norm,
                                           horizon, device)
    return out


def planning_latency(preset: str, batch_sizes=(1, 64), nfes=(1, 2, 4, 8, 15), repeats: int = 5,
                     device: str = "auto") -> list[dict]:
    """Milliseconds per plan call (whole batch) vs NFE, per method, prior time shown separately."""
    dev = resolve_device(device)
    config = preset_config("umaze", preset)
    from bridgeplan.runs import build_model

    model = build_model(config).to(dev).eval()
    rows = []
    starts = np.array([[0.9, -0.9, 0.0, 0.0]])
    goals = np.array([[-1.0, 1.0]])
    for name, planner in _planners(model, config.horizon, dev, 16).items():
        for batch in batch_sizes:
            s, g = np.repeat(starts, batch, 0), np.repeat(goals, batch, 0)
            for nfe in nfes:
                if nfe > planner.process.max_nfe:
                    continue
                gen = torch.Generator(device=dev).manual_seed(0)
                cond = planner.conditions(s, g)
                with torch.inference_mode():
                    prior_s = median_seconds(lambda: planner.prior.sample(cond, config.horizon, batch, gen),
                                             repeats, device=dev)
                total = median_seconds(lambda: planner.plan(s, g, nfe, gen), repeats, device=dev)
                rows.append({"preset": preset, "method": name, "batch": batch, "nfe": nfe,
                             "plan_ms": 1000 * total, "prior_ms": 1000 * prior_s})
    return rows


def overhead_ratios(preset: str, batch: int = 64, repeats: int = 10, device: str = "auto") -> dict:
    """Plan at NFE 1 over one bare forward pass; training step over bare forward+backward+Adam."""
    from bridgeplan.runs import build_model

    dev = resolve_device(device)
    config = preset_config("umaze", preset)
    model = build_model(config).to(dev)
    x = torch.randn(batch, config.horizon, TRANSITION_DIM, device=dev)
    t = torch.zeros(batch, device=dev)

    def bare_forward():
        with torch.inference_mode():
            model(x, t)

    planners = _planners(model.eval(), config.horizon, dev, 16)
    s = np.repeat([[0.9, -0.9, 0.0, 0.0]], batch, 0)
    g = np.repeat([[-1.0, 1.0]], batch, 0)
    gen = torch.Generator(device=dev).manual_seed(0)
    forward = median_seconds(bare_forward, repeats, device=dev)
    plan = {name: median_seconds(lambda p=p: p.plan(s, g, 1, gen), repeats, device=dev) / forward
            for name, p in planners.items()}

    model.train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)

    def bare_step():
        loss = ((model(x, t) - x) ** 2).mean()
        loss.backward()
        opt.step()
        opt.zero_grad(set_to_none=True)

    from bridgeplan.train import conditions_of

    process = DDPM(16)
    prior = make_prior("gaussian", _normalizer())

    def train_step():  # what train.py's loop does per optimizer step (grad_accum 1)
        cond = conditions_of(x)
        x1 = prior.sample(cond, config.horizon, batch, generator=gen)
        loss = process.training_loss(model, x, x1, cond, generator=gen)
        loss.backward()
        loss.item()
        opt.step()
        opt.zero_grad(set_to_none=True)

    bare = median_seconds(bare_step, repeats, device=dev)
    step = median_seconds(train_step, repeats, device=dev)
    return {"preset": preset, "batch": batch, "forward_ms": 1000 * forward, "plan_nfe1_over_forward": plan,
            "train_step_ms": 1000 * step, "bare_train_step_ms": 1000 * bare, "train_step_over_bare": step / bare}


def run_bench(out_dir: Path, presets=("cpu-small", "diffuser"), device: str = "auto", repeats: int = 5,
              eval_run: str | None = None) -> Path:
    """Run the suite and write ``bench.json`` and ``bench.md`` into ``out_dir``."""
    if repeats <= 0:
        raise BridgeplanError(f"repeats must be positive, got {repeats}")
    resolve_device(device)
    result = {"machine": machine(), "latency": [], "overhead": []}
    for preset in presets:
        result["latency"] += planning_latency(preset, repeats=repeats, device=device)
        result["overhead"].append(overhead_ratios(preset, repeats=max(repeats, 5), device=device))
    if eval_run:
        from bridgeplan.evaluate import evaluate

        t0 = time.perf_counter()
        r = evaluate(Path(eval_run), episodes=200, nfe=1, device=device)
        result["eval_throughput"] = {"run": eval_run, "episodes": 200, "nfe": 1,
                                     "seconds": time.perf_counter() - t0,
                                     "score_minari": r["score"]["minari"]}
    out_dir = Path(out_dir)
    atomic_write_text(out_dir / "bench.json", json.dumps(result, indent=2) + "\n")
    atomic_write_text(out_dir / "bench.md", format_bench(result))
    return out_dir / "bench.md"


def format_bench(result: dict) -> str:
    m = result["machine"]
    lines = ["# bridgeplan bench", "",
             f"Machine: {m['processor']}, {m['cpu_count']} cores, torch {m['torch']} with {m['torch_threads']} "
             f"threads; code {m['code_version']}. Medians over repeats after 2 warm-up calls.", "",
             "## Planning latency (ms per plan call for the whole batch; prior sampling separately)", "",
             "| preset | method | batch | NFE | plan ms | of which prior ms |", "|---|---|---|---|---|---|"]
    for r in result["latency"]:
        lines.append(f"| {r['preset']} | {r['method']} | {r['batch']} | {r['nfe']} | {r['plan_ms']:.1f} | "
                     f"{r['prior_ms']:.2f} |")
    lines += ["", "## Overheads", "",
              "| preset | batch | forward ms | plan@NFE1 / forward (worst method) | train step ms | "
              "bare step ms | train / bare |", "|---|---|---|---|---|---|---|"]
    for o in result["overhead"]:
        worst = max(o["plan_nfe1_over_forward"].items(), key=lambda kv: kv[1])
        lines.append(f"| {o['preset']} | {o['batch']} | {o['forward_ms']:.1f} | {worst[1]:.2f} ({worst[0]}) | "
                     f"{o['train_step_ms']:.1f} | {o['bare_train_step_ms']:.1f} | {o['train_step_over_bare']:.2f} |")
    if "eval_throughput" in result:
        e = result["eval_throughput"]
        lines += ["", f"Evaluation throughput: {e['episodes']} umaze episodes at NFE {e['nfe']} in "
                      f"{e['seconds']:.1f} s, planning included ({e['run']})."]
    return "\n".join(lines) + "\n"
