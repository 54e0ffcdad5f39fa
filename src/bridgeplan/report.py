"""Figures and a Markdown page from the results store (never from memory)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bridgeplan import config as cfg
from bridgeplan import paths
from bridgeplan.experiments.grids import EXPERIMENTS
from bridgeplan.experiments.store import ResultsStore
from bridgeplan.files import atomic_write_text
from bridgeplan.render import _pyplot, save_figure


def method_label(row: dict) -> str:
    """The method of a store row as its run's config names it (process parameters and training-data holds
    included: ``TrainConfig.label``)."""
    return cfg.from_dict(cfg.TrainConfig, json.loads(row["config"])).label()


def _series(rows: list[dict]) -> dict[str, list[dict]]:
    """Rows grouped into the lines of a figure: one per (method, diffusion steps, NFE, sampler, execution, task
    set); the sampler is named where it is not the process's default."""
    groups: dict[str, list[dict]] = {}
    for r in sorted(rows, key=lambda r: (r["process"], r["prior"], r["diffusion_steps"], r["multi_task"], r["nfe"],
                                         r["sampler"], r["execution"], r["step"])):
        label = " ".join(part for part in [f"{method_label(r)} N={r['diffusion_steps']} NFE={r['nfe']}",
                                           r["sampler"], r["execution"], "Multi2D" if r["multi_task"] else ""]
                         if part)
        groups.setdefault(label, []).append(r)
    return groups


def _latency(rows: list[dict]) -> str:
    """Median over seeds of the decision latency p50 / p95 at batch 1 ('-' for open loop: one plan)."""
    if rows[0]["decision_ms_p50"] is None:
        return "-"
    return (f"{np.median([r['decision_ms_p50'] for r in rows]):.1f} / "
            f"{np.median([r['decision_ms_p95'] for r in rows]):.1f}")


def _aggregate(rows: list[dict]) -> list[tuple[int, float, float, int]]:
    """(step, mean, standard error, seeds) per training step; several seeds are averaged."""
    by_step: dict[int, list[dict]] = {}
    for r in rows:
        by_step.setdefault(r["step"], []).append(r)
    out = []
    for step, rs in sorted(by_step.items()):
        means = np.array([r["score_minari"] for r in rs])
        if len(rs) == 1:
            se = rs[0]["score_minari_se"]
        else:  # across seeds: the spread of the per-seed means (it already contains the episode noise)
            se = float(means.std(ddof=1) / np.sqrt(len(rs)))
        out.append((step, float(means.mean()), se, len(rs)))
    return out


def plot_experiment(store: ResultsStore, name: str, path: Path) -> bool:
    """Score vs training steps with standard-error bands, one line per series (a colour per method, a
    line style and marker per NFE and sampler); False if no data."""
    rows = store.rows(name)
    if not rows:
        return False
    if name in EXPERIMENTS and EXPERIMENTS[name].last_snapshot_only:
        return plot_calls(rows, name, path)
    plt = _pyplot()
    def method(r: dict) -> str:
        return f"{method_label(r)} N={r['diffusion_steps']}"

    methods = list(dict.fromkeys(method(r) for r in sorted(rows, key=lambda r: (r["process"], r["prior"]))))
    samplings = {m: sorted({(r["nfe"], r["sampler"]) for r in rows if method(r) == m}) for m in methods}
    styles, markers = ["-", "--", ":", "-."], ["o", "s", "^", "D"]
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for label, srows in _series(rows).items():
        steps, mean, se = (np.array(v) for v in list(zip(*_aggregate(srows)))[:3])
        m = method(srows[0])
        color = plt.cm.tab10(methods.index(m) % 10)
        k = samplings[m].index((srows[0]["nfe"], srows[0]["sampler"]))
        ax.plot(steps, mean, marker=markers[k // len(styles) % len(markers)], ms=3, color=color,
                ls=styles[k % len(styles)], label=label)
        ax.fill_between(steps, mean - se, mean + se, color=color, alpha=0.12)
    floors = [r["floor_minari"] for r in rows if r["floor_minari"] is not None]
    if floors:
        ax.axhline(float(np.mean(floors)), color="0.5", ls="--", lw=1, label="floor (line, tracked)")
    ax.set_xlabel("training steps")
    ax.set_ylabel("normalized score (minari convention)")
    processes = {r["process"] for r in rows}
    title = EXPERIMENTS[name].title if name in EXPERIMENTS and processes <= {"ddpm", "bridge"} else name
    ax.set_title(f"{rows[0]['maze']}: {title}", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6, loc="center left", bbox_to_anchor=(1.01, 0.5))
    save_figure(fig, path)
    return True


def plot_calls(rows: list[dict], name: str, path: Path) -> bool:
    """Score against network calls per episode (log axis), mean ± standard error over seeds, one point per
    series: a colour per method, a marker per execution, filled for single-task and hollow for Multi2D; the
    floors (line prior tracked) of both task sets as grey lines."""
    plt = _pyplot()
    methods = list(dict.fromkeys(method_label(r) for r in sorted(rows, key=lambda r: (r["process"], r["prior"]))))
    executions = list(dict.fromkeys(r["execution"] for r in sorted(rows, key=lambda r: r["execution"])))
    markers = ["o", "s", "^", "D", "v", "P"]
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for label, srows in _series(rows).items():
        _, mean, se, _ = _aggregate(srows)[-1]
        r = srows[0]
        color = plt.cm.tab10(methods.index(method_label(r)) % 10)
        calls = float(np.mean([x["calls_per_episode"] for x in srows]))
        ax.errorbar([calls], [mean], yerr=[se], color=color, marker=markers[executions.index(r["execution"]) % 6],
                    mfc="none" if r["multi_task"] else color, ls="none", capsize=2, label=label)
    for multi, ls in ((0, "--"), (1, ":")):
        floors = [r["floor_minari"] for r in rows if r["multi_task"] == multi and r["floor_minari"] is not None]
        if floors:
            ax.axhline(float(np.mean(floors)), color="0.5", ls=ls, lw=1,
                       label=f"floor (line, tracked){' Multi2D' if multi else ''}")
    ax.set_xscale("log")
    ax.set_xlabel("network calls per episode")
    ax.set_ylabel("normalized score (minari convention)")
    ax.set_title(f"{rows[0]['maze']}: {name}, step {max(r['step'] for r in rows)}", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6, loc="center left", bbox_to_anchor=(1.01, 0.5))
    save_figure(fig, path)
    return True


def write_report(results_dir: Path, out_dir: Path | None = None, titles: dict[str, str] | None = None) -> Path:
    """PNG per experiment plus ``report.md`` with the tables; returns the Markdown path. ``titles``: experiments'
    titles (a study's), beside the thesis grids' own."""
    results_dir = Path(results_dir)
    out_dir = Path(out_dir) if out_dir else paths.report_dir(results_dir)
    store = ResultsStore(paths.store_path(results_dir))
    lines = ["# bridgeplan results", "",
             "Normalized scores (Minari convention unless marked d4rl): mean ± standard error over the "
             "stated episodes, made by `bridgeplan report` from the results store.", ""]
    for name in store.experiments():
        png = out_dir / f"{name}.png"
        if not plot_experiment(store, name, png):
            continue
        rows = store.rows(name)
        title = (titles or {}).get(name) or (EXPERIMENTS[name].title if name in EXPERIMENTS else name)
        lines += [f"## {name}: {title}", "", f"![{name}]({png.name})", "",
                  "| series | step | train s | NFE | episodes | seeds | score (minari) | score (d4rl) | success "
                  "| plan ms | calls/episode | decision ms p50/p95 (batch 1) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for label, srows in _series(rows).items():
            for step, mean, se, seeds in _aggregate(srows):
                at = [r for r in srows if r["step"] == step]
                d4rl = np.mean([r["score_d4rl"] for r in at])
                lines.append(
                    f"| {label} | {step} | {np.mean([r['train_seconds'] or 0 for r in at]):.0f} | "
                    f"{at[0]['nfe']} | {at[0]['episodes']} | {seeds} | {mean:.1f} ± {se:.1f} | {d4rl:.1f} | "
                    f"{np.mean([r['success_rate'] for r in at]):.2f} | {np.mean([r['plan_ms'] for r in at]):.1f} | "
                    f"{np.mean([r['calls_per_episode'] or r['nfe'] for r in at]):.0f} | {_latency(at)} |")
        lines.append("")
    path = out_dir / "report.md"
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path


def last_snapshot_table(store: ResultsStore, name: str) -> str:
    """A plain-text table of experiment ``name``'s last snapshot, one line per series (score mean ± standard error,
    success, planning time), and the floor beneath: the straight line to the goal executed the same way, no
    network (what a terminal shows after a run; ``report.md`` has every snapshot)."""
    rows = store.rows(name)
    last = max(r["step"] for r in rows)
    width = max(len(label) for label in _series(rows))
    lines = [f"{'series':<{width}}  {'score (Minari)':>15}  {'success':>7}  {'plan ms':>7}   (step {last}, "
             f"{rows[0]['episodes']} episodes)"]
    for label, srows in _series(rows).items():
        at = [r for r in srows if r["step"] == last]
        if not at:
            continue
        _, mean, se, _ = _aggregate(at)[-1]
        lines.append(f"{label:<{width}}  {f'{mean:.1f} ± {se:.1f}':>15}  "
                     f"{np.mean([r['success_rate'] for r in at]):>7.2f}  {np.mean([r['plan_ms'] for r in at]):>7.1f}")
    floors = [r["floor_minari"] for r in rows if r["step"] == last and r["floor_minari"] is not None]
    if floors:
        lines.append(f"{'the line alone (no network)':<{width}}  {float(np.mean(floors)):>15.1f}")
    return "\n".join(lines)
