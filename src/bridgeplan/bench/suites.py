"""What the bench measures, one function per figure. Networks, priors, planners, windows, optimizers
and evaluations are built through the same functions as training and evaluation (``runs``,
``train``, ``evaluate``), so the bench times what users run."""

from __future__ import annotations

import dataclasses
import os
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from bridgeplan.bench.harness import (
    busy_cores,
    empty_inductor_cache,
    interleaved_medians,
    interleaved_ratios,
    running_only,
    timed,
)
from bridgeplan.config import TrainConfig, preset_config
from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.unet import FrozenUNet
from bridgeplan.planner import Planner
from bridgeplan.processes import DDPM, Bridge, MeanFlow, Shortcut
from bridgeplan.runs import build_model, build_planner, build_prior_net, windows_of

DIFFUSION_STEPS = 16
"""N of the untrained networks timed here (the ``cpu-small`` default) unless an NFE asks for more; timings depend
on NFE, not on N."""


def diffusion_steps(nfes) -> int:
    """N of the timed networks: :data:`DIFFUSION_STEPS`, or enough for every NFE asked for (a bridge takes
    N - 1 at most)."""
    return max(DIFFUSION_STEPS, max(nfes, default=1) + 1)


def small_windows(horizon: int, stride: int = 1):
    """Windows of a small freshly generated umaze stream, and their normalizer (as training fits it)."""
    from bridgeplan.envs.maze2d.datasets import stream_from_generated
    from bridgeplan.envs.maze2d.generate import generate_stream
    from bridgeplan.envs.maze2d.grids import get_maze

    steps = 20 * horizon * stride
    stream = stream_from_generated("umaze", [generate_stream(get_maze("umaze"), steps, seed=0)])
    return windows_of(stream, horizon, stride)


def method_configs(preset: str, steps: int = DIFFUSION_STEPS, maze: str = "umaze") -> dict[str, TrainConfig]:
    """One config per method timed, at ``steps`` diffusion steps, planning ``maze``'s plans (its preset's shape): DDPM
    with each sampler, the bridge from each prior, and the processes built for one call (mean flow, shortcut) from
    the line: their network takes a second time input, which a one-call decision pays for."""
    base = preset_config(maze, preset)
    out = {}
    for sampler in DDPM.samplers:
        out[f"DDPM [{sampler}]"] = dataclasses.replace(base, process=DDPM(steps, sampler=sampler))
    for prior in ("gaussian", "line", "learned"):
        config = dataclasses.replace(base, process=Bridge(steps), prior=prior)
        out[config.label()] = config
    for process in (MeanFlow(steps), Shortcut(1 << (steps - 1).bit_length())):  # the shortcut's N: a power of 2
        config = dataclasses.replace(base, process=process, prior="line")
        out[config.label()] = config
    return out


def planners(preset: str, model: torch.nn.Module, normalizer, device: torch.device, methods=(),
             steps: int = DIFFUSION_STEPS, maze: str = "umaze") -> dict[str, Planner]:
    """Each method's planner (``methods``; empty: every one) around one (untrained) network, ``model``, or, for
    the processes whose network takes a second time input, one such network of the same preset; the learned
    prior's net is untrained too."""
    configs = {name: c for name, c in method_configs(preset, steps, maze).items() if not methods or name in methods}
    first = next(iter(configs.values()))
    prior_net = build_prior_net(first.layout, first.horizon).to(device).eval()
    interval_model = next((build_model(c).to(device).eval() for c in configs.values() if c.process.takes_interval),
                          None)
    return {name: build_planner(c, interval_model if c.process.takes_interval else model, normalizer, device,
                                prior_net=prior_net) for name, c in configs.items()}


def takes_nfe(process, nfe: int) -> bool:
    """Whether ``process`` samples in ``nfe`` calls (the shortcut model only in powers of two)."""
    try:
        process.validate_nfe(nfe)
    except BridgeplanError:
        return False
    return True


def _tasks(batch: int) -> tuple[np.ndarray, np.ndarray]:
    return np.repeat([[0.9, -0.9, 0.0, 0.0]], batch, 0), np.repeat([[-1.0, 1.0]], batch, 0)


def planning_latency(preset: str, batch_sizes, nfes, repeats: int, dev: torch.device, methods=(),
                     frozen: bool = False, maze: str = "umaze") -> list[dict]:
    """Milliseconds per plan call (whole batch) vs NFE, per method (``frozen``: and per method through its network
    traced and frozen, named ``..., frozen``), of plans of ``maze``'s shape (its preset's horizon and stride); prior
    sampling time shown separately. At each batch size every figure's calls alternate with the others'
    (:func:`interleaved_medians`)."""
    config = preset_config(maze, preset)
    model = build_model(config).to(dev).eval()
    _, normalizer = small_windows(config.horizon)
    by_name = planners(preset, model, normalizer, dev, methods, diffusion_steps(nfes), maze)
    if frozen:
        by_name |= {f"{name}, frozen": dataclasses.replace(p, model=FrozenUNet(p.model, config.horizon))
                    for name, p in by_name.items()}
    rows = []
    for batch in batch_sizes:
        starts, goals = _tasks(batch)
        calls = {}
        for name, planner in by_name.items():
            cond = planner.conditions(starts, goals)
            gen = torch.Generator(device=dev).manual_seed(0)
            calls[name, "prior"] = lambda p=planner, c=cond, g=gen: p.prior.sample(c, config.horizon, batch, g)
            for nfe in (n for n in nfes if takes_nfe(planner.process, n)):
                calls[name, nfe] = lambda p=planner, n=nfe, g=gen: p.plan(starts, goals, n, g)
        with torch.inference_mode():
            seconds = interleaved_medians(calls, repeats, dev)
        rows += [{"preset": preset, "maze": maze, "horizon": config.horizon, "stride": config.stride, "method": name,
                  "batch": batch, "nfe": nfe, "plan_ms": 1000 * s,
                  "prior_ms": 1000 * seconds[name, "prior"]} for (name, nfe), s in seconds.items() if nfe != "prior"]
    return rows


def plan_overhead(preset: str, batch: int, rounds: int, dev: torch.device, methods=()) -> dict:
    """Plan at NFE 1 over one bare forward pass of the same network on an input of the same shape (the methods
    whose network has one time input: the ratio is over that network's forward)."""
    config = preset_config("umaze", preset)
    model = build_model(config).to(dev).eval()
    _, normalizer = small_windows(config.horizon)
    x = torch.randn(batch, config.horizon, config.layout.transition_dim, device=dev)
    t = torch.zeros(batch, device=dev)
    starts, goals = _tasks(batch)
    gen = torch.Generator(device=dev).manual_seed(0)

    def forward():
        with torch.inference_mode():
            model(x, t)

    fns = {"forward": forward} | {name: (lambda p=p: p.plan(starts, goals, 1, gen))
                                  for name, p in planners(preset, model, normalizer, dev, methods).items()
                                  if not p.process.takes_interval}
    ratios = interleaved_ratios(fns, "forward", rounds, dev)
    return {"preset": preset, "batch": batch, "forward_ms": ratios.pop("forward_ms"), "plan_nfe1_over_forward": ratios}


def _train_step(config: TrainConfig, dev: torch.device, reference: bool = False):
    """``(step, bare_step)``: one optimizer step of the training loop (``TrainJob``'s own: window sampling,
    prior sample, process loss, EMA update) and a bare step with as many forward+backward passes (an MSE
    of the same network on a batch already on the device) before its one Adam step. ``reference``: with
    torch's Mish and Adam's per-parameter loop (:func:`with_torch_reference`)."""
    from bridgeplan.train import make_ema, make_optimizer, planner_job

    windows, normalizer = small_windows(config.horizon, config.stride)
    windows.to(dev)
    job = planner_job(config, normalizer, dev)
    if reference:
        with_torch_reference(job)
    model = job.model.train()
    opt = torch.optim.Adam(model.parameters(), lr=config.lr, fused=False) if reference else \
        make_optimizer(model, config.lr)
    ema = make_ema(model)
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

    return train_step, bare_step


def train_overhead(preset: str, rounds: int, dev: torch.device) -> dict:
    """The training loop's optimizer step over a bare step (see ``_train_step``)."""
    config = preset_config("umaze", preset)
    train_step, bare_step = _train_step(config, dev)
    ratios = interleaved_ratios({"bare": bare_step, "train": train_step}, "bare", rounds, dev)
    return {"preset": preset, "batch": config.batch_size, "grad_accum": config.grad_accum,
            "bare_train_step_ms": ratios["bare_ms"], "train_step_ms": ratios["bare_ms"] * ratios["train"],
            "train_step_over_bare": ratios["train"]}


def busy_core_training(preset: str, steps: int, dev: torch.device) -> dict:
    """Training steps per second, quiet and with one core kept busy by another process, at one thread
    (the default, ``device.configure_threads``) and at one thread per core (torch's own default).

    ``busy_over_quiet_1thread`` is the figure the thread default is chosen by: the rate with one core
    busy and the default threads over the quiet single-thread rate.
    """
    config = preset_config("umaze", preset)
    train_step, _ = _train_step(config, dev)
    cores = os.cpu_count() or 1
    before = torch.get_num_threads()
    rates = {}
    try:
        for busy in (0, 1):
            with busy_cores(busy):
                for threads in sorted({1, cores}):
                    torch.set_num_threads(threads)
                    train_step()  # warm-up at this thread count
                    t0 = time.perf_counter()
                    for _ in range(steps):
                        train_step()
                    rates[f"{'busy' if busy else 'quiet'}_{threads}thread"] = steps / (time.perf_counter() - t0)
    finally:
        torch.set_num_threads(before)
    return {"preset": preset, "cores": cores, "steps": steps, "steps_per_s": rates,
            "busy_over_quiet_1thread": rates["busy_1thread"] / rates["quiet_1thread"],
            f"busy_{cores}thread_over_quiet_1thread": rates[f"busy_{cores}thread"] / rates["quiet_1thread"]}


def compile_speedup(preset: str, batch_sizes, rounds: int, dev: torch.device) -> list[dict]:
    """Forward pass of ``torch.compile(model)`` against the eager model, and what compiling costs.

    Each shape is compiled twice against an inductor cache that starts empty: cold, then again after
    ``torch._dynamo.reset()`` from what the first compile cached (what a later ``eval --compile`` on the
    same machine pays). The steady-state times are interleaved rounds, like the overhead ratios.
    """
    config = preset_config("umaze", preset)
    model = build_model(config).to(dev).eval()
    rows = []
    with empty_inductor_cache(), torch.inference_mode():
        for batch in batch_sizes:
            x = torch.randn(batch, config.horizon, config.layout.transition_dim, device=dev)
            t = torch.zeros(batch, device=dev)
            first_call_s = {}
            for cache in ("cold", "cached"):
                torch._dynamo.reset()
                compiled = torch.compile(model)
                first_call_s[cache] = timed(lambda: compiled(x, t), dev)  # the first call compiles
            max_diff = float((compiled(x, t) - model(x, t)).abs().max())
            ratios = interleaved_ratios({"compiled": lambda: compiled(x, t), "eager": lambda: model(x, t)},
                                        "compiled", rounds, dev)
            rows.append({"preset": preset, "batch": batch, "eager_ms": ratios["compiled_ms"] * ratios["eager"],
                         "compiled_ms": ratios["compiled_ms"], "speedup": ratios["eager"],
                         "compile_cold_s": first_call_s["cold"], "compile_cached_s": first_call_s["cached"],
                         "max_abs_diff": max_diff})
    torch._dynamo.reset()
    return rows


def eval_throughput(run: str, device: str) -> dict:
    """Wall time of ``bridgeplan eval RUN --episodes 200 --nfe 1``, loading, planning, rollouts and floors."""
    from bridgeplan.evaluate import evaluate_run

    t0 = time.perf_counter()
    result = evaluate_run(Path(run), episodes=200, nfe=1, device=device)
    return {"run": Path(run).name, "episodes": 200, "nfe": 1, "seconds": time.perf_counter() - t0,
            "plan_ms_per_plan": result.cost["plan_ms_per_plan"], "score_minari": result.scores["score"]["minari"]}


def score_per_budget(runs, steps, budgets, episodes: int, device: str, selection_seed: int = 1,
                     test_seed: int = 0) -> dict:
    """Each run (at each of ``steps``, its EMA snapshots, or its latest checkpoint) at every budget K.

    The NFE and sampler are chosen on validation tasks (``selection_seed``): per run, step and K, the
    setting with the best mean Minari score among NFE <= K (every sampler the process has). The chosen
    setting is then scored on other, test tasks (``test_seed``): ``best`` reports that test score,
    never the selection's own. Each snapshot is loaded once; the floors are computed once per run.
    """
    from bridgeplan.envs import family_of
    from bridgeplan.evaluate import evaluate_planner, floors, make_tasks
    from bridgeplan.replan import Execution
    from bridgeplan.runs import load_planner

    evals, best = [], []
    for run in runs:
        for snapshot in steps or (None,):
            planner, info = load_planner(Path(run), snapshot=snapshot, device=device)
            tasks = {split: make_tasks(info.config.maze, episodes, seed)
                     for split, seed in (("validation", selection_seed), ("test", test_seed))}
            family = family_of(info.config.maze)
            run_floors = {split: floors(planner, family, t, Execution().resolved(family, info.config.maze))
                          for split, t in tasks.items()}
            method = planner.process.label(planner.prior.name)
            scored = {}
            for sampler in planner.process.usable_samplers() or (None,):
                sampled = planner.with_sampler(sampler) if sampler else planner
                for nfe in (k for k in budgets if takes_nfe(planner.process, k)):
                    for split in tasks:
                        r = evaluate_planner(sampled, tasks[split], nfe, run=info,
                                             precomputed_floors=run_floors[split])
                        scored[(sampler, nfe, split)] = r
                        evals.append({"method": method, "run": info.name, "step": info.step, "split": split,
                                      "train_minutes": info.elapsed_seconds / 60, "nfe": nfe,
                                      "sampler": sampler or "-", "score_minari": r.scores["score"]["minari"],
                                      "score_d4rl": r.scores["score"]["d4rl"],
                                      "success_rate": r.scores["success_rate"]["mean"],
                                      "plan_ms_per_plan": r.cost["plan_ms_per_plan"],
                                      "floor_line_minari": r.floors["floor_line"]["score"]["minari"]})
            for k in budgets:
                within = [key for key in scored if key[2] == "validation" and key[1] <= k]
                sampler, nfe, _ = max(within, key=lambda key: scored[key].scores["score"]["minari"]["mean"])
                test = scored[(sampler, nfe, "test")]
                best.append({"method": method, "run": info.name, "budget": k, "nfe": nfe, "sampler": sampler or "-",
                             "step": info.step, "train_minutes": info.elapsed_seconds / 60,
                             "validation_score_minari": scored[(sampler, nfe, "validation")].scores["score"]["minari"],
                             "score_minari": test.scores["score"]["minari"]})
    return {"episodes": episodes, "selection_seed": selection_seed, "test_seed": test_seed,
            "evaluations": evals, "best": best}


THROUGHPUT_MAZES = ("umaze", "medium", "large")
"""Plan shapes of the throughput figure: ``cpu-small``'s 128 x 1, 32 x 8 and 48 x 8 (Diffuser's 128, 256 and 384
states)."""


def matmul_size(dev: torch.device) -> int:
    """Side of the square matmul that measures a device's limit: 1024 fills a CPU, a GPU needs 8192 to
    approach its peak."""
    return 1024 if dev.type == "cpu" else 8192


def machine_limit(threads: int, dtype: torch.dtype, dev: torch.device, seconds: float = 1.0) -> dict:
    """GFLOP/s of work the machine does at its best: an n x n matmul (:func:`matmul_size`) and a large convolution
    (Diffuser's widest layer, 256 -> 256 channels, kernel 5, on 64 windows of 256 states), at ``threads`` threads."""
    n = matmul_size(dev)
    a = torch.randn(n, n, device=dev, dtype=dtype)
    x = torch.randn(64, 256, 256, device=dev, dtype=dtype)
    w = torch.randn(256, 256, 5, device=dev, dtype=dtype)
    work = {"matmul": (lambda: a @ a, 2 * n ** 3),
            "conv": (lambda: torch.nn.functional.conv1d(x, w, padding=2), 2 * 64 * 256 * 256 * 256 * 5)}
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return {name: flops / _seconds_per_call(fn, seconds, dev) / 1e9 for name, (fn, flops) in work.items()}
    finally:
        torch.set_num_threads(before)


def _seconds_per_call(fn, seconds: float, dev: torch.device) -> float:
    """Mean wall seconds per call of ``fn`` over at least ``seconds`` of calls (after two warm-up calls)."""
    fn()
    fn()
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)
    calls, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        calls += 1
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)
    return (time.perf_counter() - t0) / calls


def step_flops(config: TrainConfig, dev: torch.device) -> float:
    """FLOPs of one forward+backward of the network on one batch (torch's FLOP counter; the optimizer and the
    elementwise work are not counted, so achieved GFLOP/s are a lower bound)."""
    from torch.utils.flop_counter import FlopCounterMode

    model = build_model(config).to(dev)
    x = torch.randn(config.batch_size, config.horizon, config.layout.transition_dim, device=dev)
    with FlopCounterMode(display=False) as counter:
        model(x, torch.zeros(config.batch_size, device=dev)).square().mean().backward()
    return float(counter.get_total_flops())


def with_torch_reference(job) -> None:
    """Give a planner job's network torch's own Mish in place of bridgeplan's (with Adam's per-parameter loop,
    which ``_train_step`` picks, the implementation before bridgeplan's kernels: the throughput's reference)."""
    from bridgeplan.nets.unet import Mish

    for module in list(job.model.modules()):
        for name, child in module.named_children():
            if isinstance(child, Mish):
                setattr(module, name, torch.nn.Mish())


def training_throughput(preset: str, batch_sizes, seconds: float, dev: torch.device,
                        compiled: bool = False) -> list[dict]:
    """Training windows per second and achieved GFLOP/s of ``train.py``'s own step, per maze shape, batch and
    precision, at one thread and at one per core, quiet and with another core busy; beside each, the machine's
    limit in the same precision and threads (``machine_limit``) and the fraction of it achieved.

    ``reference`` rows run the implementation bridgeplan had before its own Mish and the fused Adam, at batch
    32 in float32: the speed-up of today's code over it is measured in the same run. ``compiled`` adds rows of
    ``train --compile``'s step (``torch.compile`` of the network, in float32) at each batch, with the seconds its
    first step took to compile from an empty inductor cache.
    """
    from bridgeplan.train import bf16_supported

    cores = os.cpu_count() or 1
    threads_list = sorted({1, cores}) if dev.type == "cpu" else [torch.get_num_threads()]
    precisions = ["fp32"] + (["bf16"] if bf16_supported(dev) else [])
    dtypes = {"fp32": torch.float32, "bf16": torch.bfloat16}
    limits = {(t, p): machine_limit(t, dtypes[p], dev) for t in threads_list for p in precisions}
    settings = [(b, p, "bridgeplan") for b in batch_sizes for p in precisions] + [(32, "fp32", "reference")] + \
        ([(b, "fp32", "compiled") for b in batch_sizes] if compiled else [])
    before = torch.get_num_threads()
    rows = []
    try:
        for maze in THROUGHPUT_MAZES:
            for batch, precision, implementation in settings:
                config = preset_config(maze, preset, batch_size=batch, precision=precision,
                                       compile=implementation == "compiled")
                flops = step_flops(config, dev) * config.grad_accum
                compile_s = None
                if config.compile:
                    torch._dynamo.reset()  # a fresh compile each time, under dynamo's limit of compiles per function
                    torch.set_num_threads(threads_list[0])
                    with empty_inductor_cache():
                        train_step, _ = _train_step(config, dev)
                        compile_s = timed(train_step, dev)  # the first step compiles
                else:
                    train_step, _ = _train_step(config, dev, reference=implementation == "reference")
                for busy in ((0, 1) if dev.type == "cpu" and cores > 1 else (0,)):
                    with busy_cores(busy):
                        for threads in threads_list:
                            torch.set_num_threads(threads)
                            step_s = _seconds_per_call(train_step, seconds, dev)
                            limit = limits[(threads, precision)]
                            rows.append({
                                "preset": preset, "maze": maze, "horizon": config.horizon, "stride": config.stride,
                                "batch": batch, "grad_accum": config.grad_accum, "precision": precision,
                                "implementation": implementation, "compile_s": compile_s,
                                "threads": threads, "busy_cores": busy, "step_ms": 1000 * step_s,
                                "windows_per_s": batch * config.grad_accum / step_s,
                                "gflop_per_step": flops / 1e9, "gflops": flops / step_s / 1e9,
                                "limit_gflops": limit, "fraction_of_matmul": flops / step_s / 1e9 / limit["matmul"],
                                "fraction_of_conv": flops / step_s / 1e9 / limit["conv"]})
    finally:
        torch.set_num_threads(before)
        if compiled:
            torch._dynamo.reset()
    return rows


def train_until_killed(maze: str, preset: str, batch: int) -> None:
    """Repeat ``train.py``'s step at ``maze``'s plan shape on one CPU thread, forever: the second job of
    :func:`side_by_side_training`. Prints a line once warm."""
    torch.set_num_threads(1)
    train_step, _ = _train_step(preset_config(maze, preset, batch_size=batch), torch.device("cpu"))
    train_step()
    print("ready", flush=True)
    while True:
        train_step()


def side_by_side_training(preset: str, seconds: float, dev: torch.device, rounds: int = 5) -> list[dict]:
    """Training windows/s of ``train.py``'s step at each maze's plan shape, at batch 32 and the preset's own, one
    thread, with the other core quiet, spinning (a Python loop), or training the same step in another process: how
    two jobs of a ``--workers 2`` study share a machine, against one job alone. The three settings alternate over
    ``rounds`` rounds (the other processes stopped and resumed, not restarted), each ``seconds / rounds`` long, so
    that a slow patch of the machine does not land on one of them only; medians over the rounds."""
    rows = []
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for maze in THROUGHPUT_MAZES:
            for batch in sorted({32, preset_config(maze, preset).batch_size}):
                rows += _side_by_side_rows(preset_config(maze, preset, batch_size=batch), seconds, rounds, dev)
    finally:
        torch.set_num_threads(before)
    return rows


def _side_by_side_rows(config: TrainConfig, seconds: float, rounds: int, dev: torch.device) -> list[dict]:
    train_step, _ = _train_step(config, dev)
    second_job = (f"from bridgeplan.bench.suites import train_until_killed; "
                  f"train_until_killed({config.maze!r}, {config.preset!r}, {config.batch_size})")
    with busy_cores(1) as spin, busy_cores(1, second_job) as job:
        others = spin + job
        running = {"quiet": [], "spinning": spin, "training": job}
        step_s: dict[str, list[float]] = {other: [] for other in running}
        for _ in range(rounds):
            for other, procs in running.items():
                running_only(others, procs)
                step_s[other].append(_seconds_per_call(train_step, seconds / rounds, dev))
    alone_s = statistics.median(step_s["quiet"])
    return [{"preset": config.preset, "maze": config.maze, "horizon": config.horizon, "stride": config.stride,
             "batch": config.batch_size, "precision": config.precision, "other_core": other, "rounds": rounds,
             "steps_per_s": 1 / statistics.median(times),
             "windows_per_s": config.batch_size * config.grad_accum / statistics.median(times),
             "beside_over_alone": alone_s / statistics.median(times)} for other, times in step_s.items()]
