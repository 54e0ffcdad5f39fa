"""The bench's Markdown: one table per figure of ``bench.json``."""

from __future__ import annotations

import json
from pathlib import Path

import torch

from bridgeplan.bench.suites import diffusion_steps, matmul_size
from bridgeplan.errors import BridgeplanError


def table(header: list[str], rows: list[list]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + [
        "| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def load_sentence(m: dict) -> str:
    """The cores' 1-minute load average at the start and the end (bench JSONs before it was recorded: none)."""
    if "load_1min_start" not in m:
        return ""
    return (f" The 1-minute load average was {m['load_1min_start']:.1f} at the start and {m['load_1min_end']:.1f} at "
            f"the end ({m['cpu_count']} cores: above 1, other processes shared the cores).")


def format_bench(result: dict) -> str:
    m = result["machine"]
    where = m.get("gpu", f"{m.get('cpu') or m['processor']}, {m['cpu_count']} cores, {m['torch_threads']} torch "
                         "threads")
    # benches made before the latency table's figures alternated timed each figure's calls in a row
    alternating = " (the latency table's figures alternating, a call of each per round)" if result.get(
        "latency_interleaved") else ""
    named = any("maze" in r for r in result["latency"])  # benches made before --mazes timed umaze's plans, unnamed
    lines = ["# bridgeplan bench", "",
             f"Device {m['device']} ({where}); torch {m['torch']}; code {m['code_version']}. Untrained networks "
             f"with N = {diffusion_steps(result['bench']['nfes'])} for the timings; medians over "
             f"{result['bench']['repeats']} repeats after 2 warm-up calls{alternating}, ratios over "
             f"{result['bench']['overhead_repeats']} interleaved rounds.{load_sentence(m)}", "",
             "## Planning latency", "", "Milliseconds per plan call for the whole batch; prior sampling is part "
             "of it and shown separately." + (" Plans: the maze whose plans are timed, their states x the steps "
                                               "between two (its preset's)." if named else ""), ""]
    lines += table(["preset", *(["plans"] if named else []), "method", "batch", "NFE", "plan ms",
                    "of which prior ms"],
                   [[r["preset"], *([f"{r['maze']}, {r['horizon']} x {r['stride']}"] if named else []),
                     r["method"], r["batch"], r["nfe"], f"{r['plan_ms']:.1f}", f"{r['prior_ms']:.2f}"]
                    for r in result["latency"]])
    if result["plan_overhead"]:
        lines += format_overheads(result)
    if result.get("busy_core"):
        lines += ["", "## Threads on a busy machine", "",
                  "Training steps per second with the machine quiet and with one core kept busy by another process "
                  "(a spinning Python), at one torch thread (bridgeplan's default on a CPU) and at one per core "
                  "(torch's own default). Target: busy / quiet >= 0.8 at the default.", ""]
        cores = result["busy_core"][0]["cores"]  # one machine: the same for every preset
        lines += table(["preset", "steps", "quiet, 1 thread", f"quiet, {cores} threads", "busy, 1 thread",
                        f"busy, {cores} threads", "busy/quiet (1 thread)", f"busy {cores} threads/quiet 1"],
                       [[b["preset"], b["steps"], *(f"{b['steps_per_s'][k]:.1f}" for k in
                         ("quiet_1thread", f"quiet_{cores}thread", "busy_1thread", f"busy_{cores}thread")),
                         f"{b['busy_over_quiet_1thread']:.2f}", f"{b[f'busy_{cores}thread_over_quiet_1thread']:.2f}"]
                        for b in result["busy_core"]])
    if result.get("throughput"):
        lines += format_throughput(result["throughput"], matmul_size(torch.device(m["device"])))
    if result.get("side_by_side"):
        lines += format_side_by_side(result["side_by_side"])
    if result["compile"]:
        lines += ["", "## torch.compile", "", "Forward pass, eager vs `torch.compile(model)` (default mode), "
                  f"medians over {result['bench']['overhead_repeats']} interleaved rounds. The first call at each "
                  "shape compiles: cold (empty inductor cache) and again from the cache the cold compile wrote.", ""]
        lines += table(["preset", "batch", "eager ms", "compiled ms", "speedup", "compile cold s", "compile cached s"],
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
        lines += format_budget(result["score_per_budget"])
    return "\n".join(lines) + "\n"


def format_overheads(result: dict) -> list[str]:
    """A plan at NFE 1 over a bare forward pass, and the training loop's step over a bare step."""
    lines = ["", "## Overheads", "", "Plan at NFE 1 over one bare forward pass of the same network and input "
             "shape (target <= 1.2):", ""]
    methods = list(result["plan_overhead"][0]["plan_nfe1_over_forward"])
    lines += table(["preset", "batch", "forward ms", *methods],
                   [[o["preset"], o["batch"], f"{o['forward_ms']:.2f}",
                     *(f"{o['plan_nfe1_over_forward'][k]:.2f}" for k in methods)] for o in result["plan_overhead"]])
    lines += ["", "Training step of `train.py` over a bare step on prepared batches: as many forward+backward "
              "passes as the loop accumulates, then one Adam step (target <= 1.15):", ""]
    lines += table(["preset", "batch x accumulated", "train step ms", "bare step ms", "train / bare"],
                   [[o["preset"], f"{o['batch']} x {o['grad_accum']}", f"{o['train_step_ms']:.1f}",
                     f"{o['bare_train_step_ms']:.1f}", f"{o['train_step_over_bare']:.2f}"]
                    for o in result["train_overhead"]])
    return lines


def format_throughput(rows: list[dict], matmul_n: int) -> list[str]:
    """Training windows/s and achieved GFLOP/s of each setting, next to the machine's limit in the same run."""
    lines = ["", "## Training throughput", "",
             "`train.py`'s own step (window gathering, prior, loss, fused Adam, EMA) at each preset's plan shape per "
             "maze; GFLOP/s count the network's forward and backward passes only (torch's FLOP counter), so they "
             f"are a lower bound. The limit is the same run's {matmul_n} x {matmul_n} matmul and a 256 -> "
             "256-channel, kernel-5 convolution on 64 x 256 states, in the same precision and threads. `reference` is "
             "the implementation before bridgeplan's own Mish and the fused Adam (torch's Mish, Adam's per-parameter "
             "loop)"
             + ("; `compiled` is `train --compile`'s step (the network through `torch.compile`), its first step "
                "compiling for the seconds shown (an empty inductor cache; a cached compile of the same shape takes "
                "a fraction)." if any(r["implementation"] == "compiled" for r in rows) else "."), ""]
    body = [[r["preset"], f"{r['maze']} {r['horizon']} x {r['stride']}", r["batch"], r["precision"],
             r["implementation"] + (f" ({r['compile_s']:.0f} s)" if r.get("compile_s") else ""), r["threads"],
             r["busy_cores"], f"{r['step_ms']:.1f}", f"{r['windows_per_s']:.0f}",
             f"{r['gflops']:.1f}", f"{r['limit_gflops']['matmul']:.0f} / {r['limit_gflops']['conv']:.0f}",
             f"{r['fraction_of_matmul']:.2f} / {r['fraction_of_conv']:.2f}"] for r in rows]
    return lines + table(["preset", "maze, plan shape", "batch", "precision", "implementation", "threads",
                          "busy cores", "step ms", "windows/s", "GFLOP/s", "limit GFLOP/s (matmul / conv)",
                          "fraction of limit"], body)


def format_side_by_side(rows: list[dict]) -> list[str]:
    """Each maze's training step alone and beside a second job: what ``--workers 2`` costs a study's runs."""
    lines = ["", "## Two jobs side by side", "",
             "`train.py`'s step at each maze's plan shape, one torch thread, with the other core quiet, spinning (a "
             "Python loop) or training the same step in another process (one thread): the two jobs of a `--workers "
             "2` study. The three settings alternate, medians over the rounds; `beside / alone`: the rate beside the "
             "other process over the quiet one.", ""]
    body = [[r["preset"], f"{r['maze']} {r['horizon']} x {r['stride']}", r["batch"], r["precision"], r["other_core"],
             f"{r['steps_per_s']:.1f}", f"{r['windows_per_s']:.0f}", f"{r['beside_over_alone']:.2f}"] for r in rows]
    return lines + table(["preset", "maze, plan shape", "batch", "precision", "other core", "steps/s", "windows/s",
                          "beside / alone"], body)


def format_budget(s: dict) -> list[str]:
    budgets = sorted({b["budget"] for b in s["best"]})
    rows = sorted(dict.fromkeys((b["run"], b["step"]) for b in s["best"]), key=lambda r: r[1])
    method = {b["run"]: b["method"] for b in s["best"]}
    shared = {m for m in method.values() if list(method.values()).count(m) > 1}
    label = {run: f"{m} ({Path(run).name})" if m in shared else m for run, m in method.items()}
    lines = ["", "## Score per planning budget", "",
             f"Normalized score (Minari convention, mean ± standard error over {s['episodes']} test episodes, "
             f"task seed {s['test_seed']}) of the best setting within K network calls per plan: NFE <= K and, "
             "for DDPM, both samplers (ancestral strided and DDIM eta 0), chosen on other, validation episodes "
             f"(task seed {s['selection_seed']}); in brackets the chosen NFE and sampler.", ""]
    body = []
    for run, step in rows:  # one block per training budget, runs in their given order
        by_k = {b["budget"]: b for b in s["best"] if (b["run"], b["step"]) == (run, step)}
        body.append([label[run], step, f"{by_k[budgets[0]]['train_minutes']:.1f}",
                      *(f"{by_k[k]['score_minari']['mean']:.1f} ± {by_k[k]['score_minari']['se']:.1f} "
                        f"({by_k[k]['nfe']}, {by_k[k]['sampler']})" for k in budgets)])
    lines += table(["method", "train steps", "train min", *(f"K = {k}" for k in budgets)], body)
    floor = next(e for e in s["evaluations"] if e["split"] == "test")["floor_line_minari"]
    lines += ["", f"No network (the straight line tracked by the controller, same episodes): "
                  f"{floor['mean']:.1f} ± {floor['se']:.1f}."]
    steps_per_run = {label[r]: {st for rr, st in rows if rr == r} for r in method}
    if len({frozenset(v) for v in steps_per_run.values()}) > 1:
        steps = "; ".join(f"{m} at {', '.join(map(str, sorted(v)))}" for m, v in steps_per_run.items())
        lines += ["", f"**Unequal training budgets** (steps): {steps}; compare with care."]
    return lines


def committed_markdown(path: Path) -> str:
    """The Markdown that ``bridgeplan bench`` wrote beside the bench JSON at ``path``, made again from it (what
    ``study report --check`` holds the committed ``bench.md`` to)."""
    try:
        return format_bench(json.loads(Path(path).read_text()))
    except OSError as e:
        raise BridgeplanError(f"cannot read bench {path}: {e.strerror or e}") from None
    except (ValueError, KeyError, TypeError, IndexError) as e:
        raise BridgeplanError(f"{path}: not a bench JSON ({type(e).__name__}: {e})") from None
