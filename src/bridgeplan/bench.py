"""Benchmarks: planning latency, overheads, torch.compile, evaluation throughput and score per planning budget.

Timings are medians over repeats after warm-up; the machine is recorded beside them. Not part of the
tests: ``bridgeplan bench`` writes ``bench.json`` (with its settings) and a Markdown table ``bench.md``.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import json
import os
import platform
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from bridgeplan.checkpoint import atomic_write_text, code_version
from bridgeplan.config import PRESETS, preset_config
from bridgeplan.data.normalizer import Normalizer
from bridgeplan.device import resolve_device
from bridgeplan.errors import BridgeplanError
from bridgeplan.planner import Planner
from bridgeplan.priors import make_prior
from bridgeplan.processes import DDPM, Bridge
from bridgeplan.runs import build_model, build_prior_net, snapshot_path, snapshot_steps
from bridgeplan.trajectory import TRANSITION_DIM

DIFFUSION_STEPS = 16
"""N of the untrained networks timed here (the ``cpu-small`` default); timings depend on NFE, not on N."""


@dataclass(frozen=True)
class BenchConfig:
    """What ``bridgeplan bench`` measures."""

    presets: tuple[str, ...] = ("cpu-small", "diffuser")
    """Networks to time (untrained; timing does not depend on the weights)."""
    batch_sizes: tuple[int, ...] = (1, 64)
    """Plans per call for the latency, overhead and compile figures."""
    nfes: tuple[int, ...] = (1, 2, 4, 8, 15)
    """Network calls per plan for the latency table."""
    repeats: int = 5
    """Timed repeats per latency figure (after 2 warm-up calls)."""
    overhead_repeats: int = 30
    """Interleaved rounds for the overhead ratios (plan vs bare forward; train step vs bare step)."""
    compile: bool = True
    """Also time ``torch.compile``'d forward passes against eager ones (compilation takes minutes on a CPU)."""
    eval_run: str = ""
    """A trained run: time 200 of its umaze episodes at NFE 1, planning included."""
    budget_runs: tuple[str, ...] = ()
    """Trained runs for the score-per-budget table, one row each (ideally one per method, at equal training steps)."""
    budget_steps: tuple[int, ...] = ()
    """Training budgets: evaluate each budget run's EMA snapshot at these steps (empty: its latest checkpoint)."""
    budgets: tuple[int, ...] = (1, 2, 4, 8)
    """Network-call budgets K of the score-per-budget table."""
    budget_episodes: int = 200
    """Episodes per evaluation of the score-per-budget table."""
    device: str = "auto"
    """``auto`` (CUDA if present), ``cpu``, ``cuda``, ..."""

    def validate(self) -> None:
        for name in ("repeats", "overhead_repeats", "budget_episodes"):
            if getattr(self, name) <= 0:
                raise BridgeplanError(f"{name.replace('_', '-')} must be positive, got {getattr(self, name)}")
        for name in ("batch_sizes", "nfes", "budgets", "budget_steps"):
            values = getattr(self, name)
            if (name != "budget_steps" and not values) or min(values, default=1) <= 0:
                raise BridgeplanError(f"{name.replace('_', '-')} must be positive integers, got {list(values)}")
        for preset in self.presets:
            if preset not in PRESETS:
                raise BridgeplanError(f"unknown preset {preset!r}: choose from {', '.join(PRESETS)}")
        for run in (self.eval_run, *self.budget_runs):
            if run and not Path(run).exists():
                raise BridgeplanError(f"no run at {run}")
        for run in self.budget_runs:
            missing = [step for step in self.budget_steps if not snapshot_path(Path(run), step).exists()]
            if missing:
                raise BridgeplanError(f"no snapshot at step {missing[0]} in {run} (have: {snapshot_steps(run)})")
        resolve_device(self.device)


def median_seconds(fn, repeats: int, device: torch.device, warmup: int = 2) -> float:
    for _ in range(warmup):
        fn()
    return statistics.median(_timed(fn, device) for _ in range(repeats))


def _timed(fn, device: torch.device) -> float:
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    t0 = time.perf_counter()
    fn()
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter() - t0


def _interleaved_ratios(fns: dict[str, object], base: str, rounds: int, device: torch.device) -> dict[str, float]:
    """Median time of each function over the median time of ``base``, timed in alternating rounds.

    Alternating keeps a slow patch of the machine (another process, a frequency change) from landing
    on one side of a ratio only.
    """
    for fn in fns.values():
        fn()
        fn()
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(rounds):
        for name, fn in fns.items():
            times[name].append(_timed(fn, device))
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


def _normalizer() -> Normalizer:
    # umaze-like limits: actions in [-1, 1], positions in [-1.5, 1.5], velocities in [-5.3, 5.3]
    return Normalizer((-1, -1, -1.5, -1.5, -5.3, -5.3), (1, 1, 1.5, 1.5, 5.3, 5.3))


def _planners(model, horizon: int, device) -> dict[str, Planner]:
    norm = _normalizer()
    learned = build_prior_net(horizon).to(device).eval()
    gaussian = make_prior("gaussian", norm)
    out = {
        "ddpm (ancestral)": Planner(model, DDPM(DIFFUSION_STEPS), gaussian, norm, horizon, device),
        "ddpm (ddim)": Planner(model, DDPM(DIFFUSION_STEPS, sampler="ddim"), gaussian, norm, horizon, device),
    }
    for prior in ("gaussian", "line", "learned"):
        out[f"bridge ({prior})"] = Planner(model, Bridge(DIFFUSION_STEPS), make_prior(prior, norm, net=learned),
                                           norm, horizon, device)
    return out


def _tasks(batch: int) -> tuple[np.ndarray, np.ndarray]:
    return np.repeat([[0.9, -0.9, 0.0, 0.0]], batch, 0), np.repeat([[-1.0, 1.0]], batch, 0)


def planning_latency(preset: str, bench: BenchConfig, dev: torch.device) -> list[dict]:
    """Milliseconds per plan call (whole batch) vs NFE, per method; prior sampling time shown separately."""
    config = preset_config("umaze", preset)
    model = build_model(config).to(dev).eval()
    rows = []
    for name, planner in _planners(model, config.horizon, dev).items():
        for batch in bench.batch_sizes:
            starts, goals = _tasks(batch)
            cond = planner.conditions(starts, goals)
            gen = torch.Generator(device=dev).manual_seed(0)
            with torch.inference_mode():
                prior_s = median_seconds(lambda: planner.prior.sample(cond, config.horizon, batch, gen),
                                         bench.repeats, dev)
            for nfe in (n for n in bench.nfes if n <= planner.process.max_nfe):
                plan_s = median_seconds(lambda: planner.plan(starts, goals, nfe, gen), bench.repeats, dev)
                rows.append({"preset": preset, "method": name, "batch": batch, "nfe": nfe,
                             "plan_ms": 1000 * plan_s, "prior_ms": 1000 * prior_s})
    return rows


def plan_overhead(preset: str, batch: int, bench: BenchConfig, dev: torch.device) -> dict:
    """Plan at NFE 1 over one bare forward pass of the same network on an input of the same shape."""
    config = preset_config("umaze", preset)
    model = build_model(config).to(dev).eval()
    x = torch.randn(batch, config.horizon, TRANSITION_DIM, device=dev)
    t = torch.zeros(batch, device=dev)
    starts, goals = _tasks(batch)
    gen = torch.Generator(device=dev).manual_seed(0)

    def forward():
        with torch.inference_mode():
            model(x, t)

    fns = {"forward": forward} | {name: (lambda p=p: p.plan(starts, goals, 1, gen))
                                  for name, p in _planners(model, config.horizon, dev).items()}
    ratios = _interleaved_ratios(fns, "forward", bench.overhead_repeats, dev)
    return {"preset": preset, "batch": batch, "forward_ms": ratios.pop("forward_ms"), "plan_nfe1_over_forward": ratios}


def _windows(horizon: int):
    """Training windows of a small freshly generated umaze stream, and their normalizer."""
    from bridgeplan.data import WindowDataset
    from bridgeplan.data.datasets import stream_from_generated
    from bridgeplan.data.generate import generate_stream
    from bridgeplan.maze.layouts import get_maze

    stream = stream_from_generated("umaze", [generate_stream(get_maze("umaze"), 20 * horizon, seed=0)])
    normalizer = Normalizer.fit(stream.transitions())
    return WindowDataset(stream, horizon, normalizer), normalizer


def train_overhead(preset: str, bench: BenchConfig, dev: torch.device) -> dict:
    """One optimizer step of the training loop over a bare forward+backward+Adam step on a prepared batch.

    The loop's step is ``TrainJob``'s own (window sampling, prior sample, process loss, EMA update), at the
    preset's batch size and gradient accumulation; the bare step does the same number of forward+backward
    passes (an MSE of the same network on a batch already on the device) before its one Adam step.
    """
    from bridgeplan.train import planner_job

    config = preset_config("umaze", preset)
    windows, normalizer = _windows(config.horizon)
    job = planner_job(config, normalizer, dev)
    model = job.model.train()
    opt = torch.optim.Adam(model.parameters(), lr=config.lr)
    ema = copy.deepcopy(model).requires_grad_(False)
    gen = torch.Generator(device=dev).manual_seed(0)
    step = config.ema_start  # past the EMA's warm-up copy: the steady state of a long run
    x = windows.batch(torch.arange(config.batch_size)).to(dev)
    t = torch.zeros(config.batch_size, device=dev)

    def bare_step():
        for _ in range(config.grad_accum):
            ((model(x, t) - x) ** 2).mean().backward()
        opt.step()
        opt.zero_grad(set_to_none=True)

    def train_step():
        nonlocal step
        job.accumulate_gradients(windows, gen, dev)
        step += 1
        job.apply_gradients(opt, ema, step)

    ratios = _interleaved_ratios({"bare": bare_step, "train": train_step}, "bare", bench.overhead_repeats, dev)
    return {"preset": preset, "batch": config.batch_size, "grad_accum": config.grad_accum,
            "bare_train_step_ms": ratios["bare_ms"], "train_step_ms": ratios["bare_ms"] * ratios["train"],
            "train_step_over_bare": ratios["train"]}


def compile_speedup(preset: str, bench: BenchConfig, dev: torch.device) -> list[dict]:
    """Forward pass of ``torch.compile(model)`` against the eager model, and what compiling costs.

    Each shape is compiled twice against an inductor cache that starts empty: cold, then again after
    ``torch._dynamo.reset()`` from what the first compile cached (what a later ``eval --compile`` on the
    same machine pays). The steady-state times are interleaved rounds, like the overhead ratios.
    """
    config = preset_config("umaze", preset)
    model = build_model(config).to(dev).eval()
    rows = []
    with _empty_inductor_cache(), torch.inference_mode():
        for batch in bench.batch_sizes:
            x = torch.randn(batch, config.horizon, TRANSITION_DIM, device=dev)
            t = torch.zeros(batch, device=dev)
            first_call_s = {}
            for cache in ("cold", "cached"):
                torch._dynamo.reset()
                compiled = torch.compile(model)
                first_call_s[cache] = _timed(lambda: compiled(x, t), dev)  # the first call compiles
            max_diff = float((compiled(x, t) - model(x, t)).abs().max())
            ratios = _interleaved_ratios({"compiled": lambda: compiled(x, t), "eager": lambda: model(x, t)},
                                         "compiled", bench.overhead_repeats, dev)
            rows.append({"preset": preset, "batch": batch, "eager_ms": ratios["compiled_ms"] * ratios["eager"],
                         "compiled_ms": ratios["compiled_ms"], "speedup": ratios["eager"],
                         "compile_cold_s": first_call_s["cold"], "compile_cached_s": first_call_s["cached"],
                         "max_abs_diff": max_diff})
    torch._dynamo.reset()
    return rows


@contextlib.contextmanager
def _empty_inductor_cache():
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


def eval_throughput(run: str, device: str) -> dict:
    """Wall time of ``bridgeplan eval RUN --episodes 200 --nfe 1``, planning, rollouts and floors included."""
    from bridgeplan.evaluate import evaluate

    t0 = time.perf_counter()
    result = evaluate(Path(run), episodes=200, nfe=1, device=device)
    return {"run": run, "episodes": 200, "nfe": 1, "seconds": time.perf_counter() - t0,
            "plan_ms_per_plan": result["plan_ms_per_plan"], "score_minari": result["score"]["minari"]}


def score_per_budget(bench: BenchConfig) -> dict:
    """Every run evaluated at each budget K (DDPM with both samplers), and the best score within K calls.

    Each run is evaluated at each of ``budget_steps`` (its EMA snapshots) or, without them, at its latest
    checkpoint. ``best`` holds, per run, training step and K, the evaluation with the highest mean Minari
    score among those with NFE <= K (never pooled across runs, so two seeds of one method stay two rows);
    a method whose process allows fewer calls than K keeps its best at fewer.
    """
    from bridgeplan.evaluate import evaluate
    from bridgeplan.runs import load_planner

    evals = []
    for run in bench.budget_runs:
        planner, info = load_planner(Path(run), device=bench.device)
        samplers = ("ancestral", "ddim") if info["config"].process.name == "ddpm" else (None,)
        for snapshot in bench.budget_steps or (None,):
            for sampler in samplers:
                for nfe in (k for k in bench.budgets if k <= planner.process.max_nfe):
                    r = evaluate(Path(run), episodes=bench.budget_episodes, nfe=nfe, sampler=sampler,
                                 snapshot=snapshot, device=bench.device)
                    method = "ddpm" if r["process"] == "ddpm" else f"bridge ({r['prior']})"
                    evals.append({"method": method, "run": run, "step": r["step"],
                                  "train_minutes": r["train_seconds"] / 60, "nfe": nfe, "sampler": r["sampler"],
                                  "score_minari": r["score"]["minari"], "score_d4rl": r["score"]["d4rl"],
                                  "success_rate": r["success_rate"]["mean"],
                                  "plan_ms_per_plan": r["plan_ms_per_plan"],
                                  "floor_line_minari": r["floor_line"]["score"]["minari"]})
    best = []
    for run, step in dict.fromkeys((e["run"], e["step"]) for e in evals):
        for k in bench.budgets:
            within = [e for e in evals if (e["run"], e["step"]) == (run, step) and e["nfe"] <= k]
            top = max(within, key=lambda e: e["score_minari"]["mean"])
            best.append({"method": top["method"], "run": run, "budget": k, "nfe": top["nfe"],
                         "sampler": top["sampler"], "step": step, "train_minutes": top["train_minutes"],
                         "score_minari": top["score_minari"]})
    return {"episodes": bench.budget_episodes, "evaluations": evals, "best": best}


def run_bench(out_dir: Path, bench: BenchConfig, progress=print) -> Path:
    """Run the suite and write ``bench.json`` and ``bench.md`` into ``out_dir``; returns the Markdown path."""
    bench.validate()
    dev = resolve_device(bench.device)
    result = {"bench": dataclasses.asdict(bench), "machine": machine(dev), "latency": [], "plan_overhead": [],
              "train_overhead": [], "compile": []}
    for preset in bench.presets:
        progress(f"[{preset}] planning latency")
        result["latency"] += planning_latency(preset, bench, dev)
        progress(f"[{preset}] overheads")
        result["plan_overhead"] += [plan_overhead(preset, b, bench, dev) for b in bench.batch_sizes]
        result["train_overhead"].append(train_overhead(preset, bench, dev))
        if bench.compile:
            progress(f"[{preset}] torch.compile")
            result["compile"] += compile_speedup(preset, bench, dev)
    if bench.eval_run:
        progress("evaluation throughput")
        result["eval_throughput"] = eval_throughput(bench.eval_run, bench.device)
    if bench.budget_runs:
        progress("score per planning budget")
        result["score_per_budget"] = score_per_budget(bench)
    out_dir = Path(out_dir)
    atomic_write_text(out_dir / "bench.json", json.dumps(result, indent=2) + "\n")
    atomic_write_text(out_dir / "bench.md", format_bench(result))
    return out_dir / "bench.md"


def _table(header: list[str], rows: list[list]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + [
        "| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def format_bench(result: dict) -> str:
    m = result["machine"]
    where = m.get("gpu", f"{m['processor']}, {m['cpu_count']} cores, {m['torch_threads']} torch threads")
    lines = ["# bridgeplan bench", "",
             f"Device {m['device']} ({where}); torch {m['torch']}; code {m['code_version']}. Untrained networks "
             f"with N = {DIFFUSION_STEPS} for the timings; medians over {result['bench']['repeats']} repeats after "
             f"2 warm-up calls, ratios over {result['bench']['overhead_repeats']} interleaved rounds.", "",
             "## Planning latency", "", "Milliseconds per plan call for the whole batch; prior sampling is part "
             "of it and shown separately.", ""]
    lines += _table(["preset", "method", "batch", "NFE", "plan ms", "of which prior ms"],
                    [[r["preset"], r["method"], r["batch"], r["nfe"], f"{r['plan_ms']:.1f}", f"{r['prior_ms']:.2f}"]
                     for r in result["latency"]])
    lines += ["", "## Overheads", "", "Plan at NFE 1 over one bare forward pass of the same network and input "
              "shape (target <= 1.2):", ""]
    methods = list(result["plan_overhead"][0]["plan_nfe1_over_forward"]) if result["plan_overhead"] else []
    lines += _table(["preset", "batch", "forward ms", *methods],
                    [[o["preset"], o["batch"], f"{o['forward_ms']:.2f}",
                      *(f"{o['plan_nfe1_over_forward'][k]:.2f}" for k in methods)] for o in result["plan_overhead"]])
    lines += ["", "Training step of `train.py` over a bare step on prepared batches: as many forward+backward "
              "passes as the loop accumulates, then one Adam step (target <= 1.15):", ""]
    lines += _table(["preset", "batch x accumulated", "train step ms", "bare step ms", "train / bare"],
                    [[o["preset"], f"{o['batch']} x {o['grad_accum']}", f"{o['train_step_ms']:.1f}",
                      f"{o['bare_train_step_ms']:.1f}", f"{o['train_step_over_bare']:.2f}"]
                     for o in result["train_overhead"]])
    if result["compile"]:
        lines += ["", "## torch.compile", "", "Forward pass, eager vs `torch.compile(model)` (default mode), "
                  f"medians over {result['bench']['overhead_repeats']} interleaved rounds. The first call at each "
                  "shape compiles: cold (empty inductor cache) and again from the cache the cold compile wrote.", ""]
        lines += _table(["preset", "batch", "eager ms", "compiled ms", "speedup", "compile cold s", "compile cached s"],
                        [[c["preset"], c["batch"], f"{c['eager_ms']:.2f}", f"{c['compiled_ms']:.2f}",
                          f"{c['speedup']:.2f}", f"{c['compile_cold_s']:.1f}", f"{c['compile_cached_s']:.1f}"]
                         for c in result["compile"]])
    if "eval_throughput" in result:
        e = result["eval_throughput"]
        lines += ["", "## Evaluation throughput", "",
                  f"{e['episodes']} umaze episodes at NFE {e['nfe']} in {e['seconds']:.1f} s, planning, rollouts "
                  f"and the straight-line floor included ({e['plan_ms_per_plan']:.2f} ms per plan; run {e['run']}, "
                  f"score {e['score_minari']['mean']:.1f} ± {e['score_minari']['se']:.1f})."]
    if "score_per_budget" in result:
        lines += _format_budget(result["score_per_budget"])
    return "\n".join(lines) + "\n"


def _format_budget(s: dict) -> list[str]:
    budgets = sorted({b["budget"] for b in s["best"]})
    rows = sorted(dict.fromkeys((b["run"], b["step"]) for b in s["best"]), key=lambda r: r[1])
    method = {b["run"]: b["method"] for b in s["best"]}
    shared = {m for m in method.values() if list(method.values()).count(m) > 1}
    label = {run: f"{m} ({Path(run).name})" if m in shared else m for run, m in method.items()}
    lines = ["", "## Score per planning budget", "",
             f"Best normalized score (Minari convention, mean ± standard error over {s['episodes']} episodes, "
             "seed 0) within K network calls per plan, over NFE <= K and, for DDPM, both samplers "
             "(ancestral strided and DDIM eta 0); in brackets the NFE and sampler that reached it.", ""]
    table = []
    for run, step in rows:  # one block per training budget, runs in their given order
        by_k = {b["budget"]: b for b in s["best"] if (b["run"], b["step"]) == (run, step)}
        table.append([label[run], step, f"{by_k[budgets[0]]['train_minutes']:.1f}",
                      *(f"{by_k[k]['score_minari']['mean']:.1f} ± {by_k[k]['score_minari']['se']:.1f} "
                        f"({by_k[k]['nfe']}, {by_k[k]['sampler']})" for k in budgets)])
    lines += _table(["method", "train steps", "train min", *(f"K = {k}" for k in budgets)], table)
    floor = s["evaluations"][0]["floor_line_minari"]
    lines += ["", f"No network (the straight line tracked by the controller, same episodes): "
                  f"{floor['mean']:.1f} ± {floor['se']:.1f}."]
    steps_per_run = {label[r]: {st for rr, st in rows if rr == r} for r in method}
    if len({frozenset(v) for v in steps_per_run.values()}) > 1:
        steps = "; ".join(f"{m} at {', '.join(map(str, sorted(v)))}" for m, v in steps_per_run.items())
        lines += ["", f"**Unequal training budgets** (steps): {steps}; compare with care."]
    return lines
