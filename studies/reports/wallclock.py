"""Score at equal wall-clock: training settings compared at the same minutes of training, not the same steps.

Each arm is a training setting (batch, learning rate, precision); each run trains for a wall-clock budget with
``train --minutes M`` (resumed with a larger M for the next budget), side by side with the run of the other arm
and the same seed, one torch thread each. Its final EMA snapshot is evaluated at several NFEs on test episodes
(task seed = training seed) and on validation episodes (task seed + 1000). The NFE is chosen per arm and budget
on the validation episodes (best mean over seeds) and reported on the test episodes; the difference between the
arms is paired per seed (:func:`bridgeplan.analysis.stats.paired`), with its verdict at two standard errors.

:func:`collect` turns the evaluation JSONs of a campaign into ``results.csv`` (one row per evaluation, every key,
the dataset named by what it is); :func:`render` makes the report from the committed CSVs. Made by
`bridgeplan study report throughput-wallclock` (studies/throughput-wallclock.toml).

Its last sections (:func:`methods_lines`, one per :data:`PAIRINGS`) pair two grid studies' runs per method, NFE and
seed. Whether large keeps learning when the faster setting gets the old runs' wall-clock: large-v2-curves at step
16000 (batch 32, fp32, ~9-10 minutes each, two side by side) against large-v2-batch256 at the steps batch 256 in
bf16 makes in that time. What the precision alone changes: large-v2-batch256 against large-v2-batch256-fp32 at the
same steps. Nothing is selected: every NFE both evaluated is shown, the difference paired per seed at each.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bridgeplan.analysis.keys import label, method
from bridgeplan.analysis.load import Point, load_csvs
from bridgeplan.analysis.stats import compare, mean_se, paired
from bridgeplan.analysis.tables import fmt_diff, fmt_mean_se, table
from bridgeplan.errors import BridgeplanError
from bridgeplan.evaluate import VALIDATION_SEED_OFFSET
from bridgeplan.files import atomic_write_text

FOLDER = "throughput-wallclock"
"""Its folder under docs/results: one ``<maze>/results.csv`` per maze."""
MAZES = ("medium", "large")
METHODS = (method("ddpm", steps=16), method("bridge", "line", steps=16), method("flow", "line", steps=16))
READS = METHODS
"""The grids' runs its last section reads (its first sections' runs are its own arms: the module's docstring)."""


@dataclass(frozen=True)
class Pairing:
    """One of the last sections: a store's runs at a step against another store's at its step."""

    maze: str
    before: tuple[str, int]
    """The old store (docs/results/<store>/results.csv) and the snapshot step read of it."""
    after: tuple[str, int]
    wallclock: bool
    """Whether both stores' runs trained on one machine (two side by side, one thread each), so that their minutes
    compare; otherwise the section compares their scores at the steps given and shows no minutes."""


PAIRINGS = (Pairing("large", ("large-v2-curves", 16000), ("large-v2-batch256", 6400), wallclock=True),
            Pairing("large", ("large-v2-batch256", 6400), ("large-v2-batch256-fp32", 6400), wallclock=False))
"""The last sections: the new store's steps are what its setting makes in the old runs' wall-clock (the first), the
same steps on another CPU (the second: docs/results/throughput-avx2)."""
FIELDS = ("maze", "arm", "batch_size", "lr", "precision", "seed", "minutes", "step", "train_seconds",
          "windows_per_s", "nfe", "split", "eval_seed", "episodes", "score_minari", "score_minari_se",
          "success_rate", "floor_line_minari", "process", "dataset", "code_version")


def arm_name(config: dict) -> str:
    """An arm by its training setting: ``batch 256, lr 0.003, bf16``."""
    return f"batch {config['batch_size']}, lr {config['lr']:g}, {config.get('precision', 'fp32')}"


def row_of(evaluation: dict) -> dict:
    """The CSV row of one evaluation JSON (``bridgeplan eval --out``): no path of the machine that made it."""
    config = evaluation["config"]
    validation = evaluation["seed"] >= VALIDATION_SEED_OFFSET
    return {"maze": evaluation["maze"], "arm": arm_name(config), "batch_size": config["batch_size"],
            "lr": config["lr"], "precision": config.get("precision", "fp32"),
            "seed": evaluation["seed"] - (VALIDATION_SEED_OFFSET if validation else 0),
            "minutes": config["minutes"], "step": evaluation["step"], "train_seconds": evaluation["train_seconds"],
            "windows_per_s": evaluation["step"] * config["batch_size"] * config["grad_accum"]
            / evaluation["train_seconds"],
            "nfe": evaluation["nfe"], "split": "validation" if validation else "test", "eval_seed": evaluation["seed"],
            "episodes": evaluation["episodes"], "score_minari": evaluation["score"]["minari"]["mean"],
            "score_minari_se": evaluation["score"]["minari"]["se"], "success_rate": evaluation["success_rate"]["mean"],
            "floor_line_minari": evaluation["floor_line"]["score"]["minari"]["mean"],
            "process": evaluation["process"], "dataset": Path(config["dataset"]).name,
            "code_version": evaluation["environment"]["code_version"]}


def collect(eval_jsons, out_csv: Path) -> int:
    """Write the rows of ``eval_jsons`` (paths) to ``out_csv``, sorted by every key; returns the row count."""
    rows = sorted((row_of(json.loads(Path(p).read_text())) for p in eval_jsons),
                  key=lambda r: (r["arm"], r["seed"], r["minutes"], r["split"], r["nfe"]))
    if not rows:
        raise BridgeplanError("no evaluation JSONs to collect")
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(Path(out_csv), text.getvalue())
    return len(rows)


_FLOATS = {"lr", "minutes", "train_seconds", "windows_per_s", "score_minari", "score_minari_se", "success_rate",
           "floor_line_minari"}


def read(path: Path) -> list[dict]:
    """The rows of a ``results.csv`` written by :func:`collect`, numbers as numbers."""
    numeric = {"batch_size": int, "seed": int, "step": int, "nfe": int, "eval_seed": int, "episodes": int}
    with open(path, newline="") as f:
        return [{k: numeric.get(k, float)(v) if k in numeric or k in _FLOATS else v for k, v in r.items()}
                for r in csv.DictReader(f)]



def maze_table(rows: list[dict]) -> list[str]:
    """The table of one maze: per budget and arm, the chosen NFE's test score, success and speed; the paired
    difference of each arm from the first (the slowest in windows/s, the baseline)."""
    arms = sorted({r["arm"] for r in rows}, key=lambda a: np.mean([r["windows_per_s"] for r in rows
                                                                    if r["arm"] == a]))
    body, diffs = [], []
    for minutes in sorted({r["minutes"] for r in rows}):
        at = [r for r in rows if r["minutes"] == minutes]
        chosen = {}
        for arm in arms:
            mine = [r for r in at if r["arm"] == arm]
            validation = {nfe: np.mean([r["score_minari"] for r in mine if r["nfe"] == nfe and r["split"] ==
                                        "validation"]) for nfe in sorted({r["nfe"] for r in mine})}
            nfe = max(validation, key=validation.get)  # first best in NFE order on ties
            test = {r["seed"]: r for r in mine if r["nfe"] == nfe and r["split"] == "test"}
            chosen[arm] = test
            body.append([f"{minutes:g}", arm, f"{np.mean([r['step'] for r in test.values()]):.0f}",
                         f"{np.mean([r['windows_per_s'] for r in test.values()]):.0f}", nfe,
                         fmt_mean_se({s: r["score_minari"] for s, r in test.items()}),
                         fmt_mean_se({s: r["success_rate"] for s, r in test.items()}, digits=3), len(test)])
        base = arms[0]
        for arm in arms[1:]:
            d = paired({s: r["score_minari"] for s, r in chosen[arm].items()},
                       {s: r["score_minari"] for s, r in chosen[base].items()})
            ds = paired({s: r["success_rate"] for s, r in chosen[arm].items()},
                        {s: r["success_rate"] for s, r in chosen[base].items()})
            diffs.append([f"{minutes:g}", f"{arm} - {base}", fmt_diff(d), compare(d), fmt_diff(ds, digits=3),
                          compare(ds)])
    floor = mean_se({r["seed"]: r["floor_line_minari"] for r in rows if r["split"] == "test"})
    lines = table(["minutes", "arm", "steps", "windows/s", "NFE (validation)", "Minari score (test)",
                   "success rate", "seeds"], body)
    lines += ["", *table(["minutes", "difference", "score, per seed", "verdict", "success, per seed", "verdict"],
                         diffs)]
    return lines + ["", f"The straight line alone, tracked, on the same test episodes: {fmt_mean_se(floor)}."]


def _arm_of_store(path: Path, step: int) -> str:
    """The training setting (:func:`arm_name`) of a store's rows at ``step``, from their configs."""
    with open(path, newline="") as f:
        arms = {arm_name(json.loads(r["config"])) for r in csv.DictReader(f) if int(r["step"]) == step}
    if len(arms) != 1:
        raise BridgeplanError(f"{path}: expected one training setting at step {step}, found {sorted(arms) or 'none'}")
    return arms.pop()


def methods_lines(root: Path) -> list[str]:
    """One section per pairing of :data:`PAIRINGS` whose stores are both committed (:func:`pairing_lines`)."""
    return [line for pairing in PAIRINGS for line in pairing_lines(Path(root), pairing)]


def pairing_lines(root: Path, pairing: Pairing) -> list[str]:
    """Per method and NFE, the old store's runs at its step against the new store's at its step, on the test
    episodes: score and success, each with its paired difference (new minus old) and verdict; nothing where a
    store is absent."""
    before, after = pairing.before, pairing.after
    paths = [root / store / "results.csv" for store, _ in (before, after)]
    if not all(p.exists() for p in paths):
        return []
    old_rows, new_rows = (load_csvs([p]) for p in paths)
    old_step, new_step = before[1], after[1]
    arms = [_arm_of_store(p, step) for p, step in zip(paths, (old_step, new_step))]
    body = []
    for key in METHODS:
        old_nfes = old_rows.nfes(key, old_step)
        for nfe in sorted(n for n in new_rows.nfes(key, new_step) if n in old_nfes):
            old, new = Point(key, old_step, nfe), Point(key, new_step, nfe)
            cells = [" / ".join(f"{np.mean(list(r.values(p, field='train_seconds').values())) / 60:.1f}"
                                for r, p in ((old_rows, old), (new_rows, new)))] if pairing.wallclock else []
            for field, digits in (("score", 1), ("success", 3)):
                was, now = old_rows.values(old, field=field), new_rows.values(new, field=field)
                d = paired(now, was)
                cells += [fmt_mean_se(was, digits=digits), fmt_mean_se(now, digits=digits), fmt_diff(d, digits=digits),
                          compare(d)]
            body.append([label(key), nfe, *cells, len(new_rows.rows(new))])
    stores = f"Before: {arms[0]}, step {old_step} ({before[0]}); after: {arms[1]}, step {new_step} ({after[0]}). "
    if pairing.wallclock:
        title = f"## {pairing.maze}: every method at the old runs' wall-clock, {arms[1]}"
        how = ("Minutes: each run's training wall-clock at that step, mean over seeds (two runs side by side, one "
               "thread each). ")
    else:
        title = f"## {pairing.maze}: {arms[1]} against {arms[0]}, at equal steps"
        how = "The two stores' runs trained on different CPUs: their minutes are not compared. "
    header = ["method", "NFE", *(["minutes before / after"] if pairing.wallclock else []), "score before",
              "score after", "difference", "verdict", "success before", "success after", "difference", "verdict",
              "seeds"]
    return ["", title, "", stores + how + "Test episodes (200 per seed, task seed = training seed); every NFE both "
            "evaluated, nothing chosen; differences after - before, paired per seed.", "", *table(header, body)]


def render(root: Path) -> str:
    lines = ["# Score at equal wall-clock", "",
             "Generated by `bridgeplan study report throughput-wallclock` from "
             f"`docs/results/{FOLDER}/<maze>/results.csv`; do not edit. DDPM, `cpu-small`, each run trained for the "
             "minutes in its row on one torch thread, side by side with the same seed's run of the other arm; "
             "the final EMA snapshot evaluated on 200 test episodes (task seed = training seed) and 200 "
             "validation episodes (task seed + 1000). The NFE is chosen on the validation episodes; scores "
             "(Minari convention) and success rates are mean ± standard error over training seeds; the "
             "differences are paired per seed, verdict at two standard errors."]
    found = False
    for maze in MAZES:
        path = Path(root) / FOLDER / maze / "results.csv"
        if not path.exists():
            continue
        found = True
        rows = read(path)
        versions = sorted({r["code_version"] for r in rows})
        lines += ["", f"## {maze}", "", f"Dataset {', '.join(sorted({r['dataset'] for r in rows}))}; code "
                  f"{', '.join(versions)}.", "", *maze_table(rows)]
    if not found:
        raise BridgeplanError(f"no {FOLDER}/<maze>/results.csv under {root}")
    return "\n".join(lines + methods_lines(Path(root)))
