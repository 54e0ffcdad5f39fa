"""The score-at-equal-wall-clock report: evaluation JSONs to rows (no machine paths), NFE chosen on validation,
paired differences, against a table computed by hand."""

from __future__ import annotations

import json

from tests.reports import GENERATORS, report

wallclock = report("wallclock")
FOLDER, collect = wallclock.FOLDER, wallclock.collect

ARMS = {"A": {"batch_size": 32, "lr": 0.001, "precision": "fp32", "step": 9000},
        "B": {"batch_size": 256, "lr": 0.003, "precision": "bf16", "step": 3300}}
# validation: A is best at NFE 2, B at NFE 1; test at those NFEs, per seed 0, 1, 2
VALIDATION = {("A", 1): 80.0, ("A", 2): 82.0, ("B", 1): 85.0, ("B", 2): 84.0}
TEST = {("A", 2): [70.0, 72.0, 74.0], ("B", 1): [80.0, 83.0, 80.0], ("A", 1): [99.0] * 3, ("B", 2): [99.0] * 3}
SUCCESS = {"A": 0.9, "B": 0.95}


def evaluation(arm, seed, nfe, split):
    a = ARMS[arm]
    score = VALIDATION[(arm, nfe)] if split == "validation" else TEST[(arm, nfe)][seed]
    return {"run": f"/somewhere/on/this/machine/{arm}-s{seed}", "step": a["step"], "train_seconds": 300.0,
            "maze": "medium", "process": "ddpm", "nfe": nfe, "episodes": 200,
            "seed": seed + (1000 if split == "validation" else 0),
            "score": {"minari": {"mean": score, "se": 1.0}}, "success_rate": {"mean": SUCCESS[arm], "se": 0.0},
            "floor_line": {"score": {"minari": {"mean": 40.0 + seed, "se": 1.0}}},
            "environment": {"code_version": "0.1.0+abc1234"},
            "config": {"dataset": "/somewhere/datasets/medium-1000000", "batch_size": a["batch_size"],
                       "lr": a["lr"], "precision": a["precision"], "minutes": 5.0, "grad_accum": 1}}


def test_wallclock_report_against_a_hand_computed_table(tmp_path):
    paths = []
    for arm in ARMS:
        for seed in range(3):
            for nfe in (1, 2):
                for split in ("test", "validation"):
                    paths.append(tmp_path / f"{arm}-{seed}-{nfe}-{split}.json")
                    paths[-1].write_text(json.dumps(evaluation(arm, seed, nfe, split)))
    csv_path = tmp_path / "results" / FOLDER / "medium" / "results.csv"
    csv_path.parent.mkdir(parents=True)
    assert collect(paths, csv_path) == 24
    text = csv_path.read_text()
    assert "/somewhere" not in text and ",medium-1000000," in text  # the dataset by what it is, no paths
    report = GENERATORS["wallclock"].render(tmp_path / "results")
    # A: NFE 2 on validation, test 70/72/74 -> 72.0 ± 1.2 (sd 2); B: NFE 1, test 80/83/80 -> 81.0 ± 1.0 (sd 1.73)
    # windows/s: 9000 x 32 / 300 = 960 and 3300 x 256 / 300 = 2816, so A is the baseline
    assert "| 5 | batch 32, lr 0.001, fp32 | 9000 | 960 | 2 | 72.0 ± 1.2 | 0.900 ± 0.000 | 3 |" in report
    assert "| 5 | batch 256, lr 0.003, bf16 | 3300 | 2816 | 1 | 81.0 ± 1.0 | 0.950 ± 0.000 | 3 |" in report
    # per seed B - A: 10, 11, 6 -> +9.0 ± 1.5 (sd sqrt 7), better; success +0.05 everywhere
    assert ("| 5 | batch 256, lr 0.003, bf16 - batch 32, lr 0.001, fp32 | +9.0 ± 1.5 | better | +0.050 ± 0.000 "
            "| better |") in report
    assert "tracked, on the same test episodes: 41.0 ± 0.6." in report  # floors 40, 41, 42 (both arms' rows)
    assert "code 0.1.0+abc1234" in report and "Dataset medium-1000000" in report


def store_row(process, prior, seed, step, nfe, score, success, batch, seconds, precision=None):
    config = {"process": {"name": process, "steps": 16}, "prior": prior, "batch_size": batch,
              "lr": 0.001 if batch == 32 else 0.003, "precision": precision or ("fp32" if batch == 32 else "bf16")}
    return {"id": 1, "experiments": "nfe-curves", "run_name": f"{process}-s{seed}", "maze": "large",
            "process": process, "prior": prior, "diffusion_steps": 16, "seed": seed, "step": step,
            "train_seconds": seconds, "nfe": nfe, "episodes": 200, "eval_seed": seed, "split": "test",
            "score_minari": score, "score_minari_se": 1.0, "success_rate": success, "plan_ms": 1.0,
            "floor_minari": 38.0, "config": json.dumps(config), "code_version": "0.1.0+abc1234"}


def write_store(folder, rows):
    """A store's committed rows: ``folder/results.csv``."""
    import csv

    folder.mkdir()
    with open(folder / "results.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_the_methods_section_pairs_every_common_nfe_of_the_two_stores(tmp_path):
    PAIRINGS, methods_lines = wallclock.PAIRINGS, wallclock.methods_lines

    BEFORE, AFTER = PAIRINGS[0].before, PAIRINGS[0].after
    before = {("ddpm", "gaussian"): [50.0, 52.0, 54.0], ("flow", "line"): [60.0, 60.0, 60.0]}
    after = {("ddpm", "gaussian"): [61.0, 62.0, 63.0], ("flow", "line"): [59.0, 60.0, 64.0]}
    for (store, step), scores, batch, seconds in ((BEFORE, before, 32, 570.0), (AFTER, after, 256, 600.0)):
        rows = [store_row(p, q, seed, step, nfe, s + nfe, 0.5 + s / 200, batch, seconds)
                for (p, q), values in scores.items() for seed, s in enumerate(values) for nfe in (1, 2)]
        if store == AFTER[0]:  # NFE 4 in one store only
            rows += [store_row("ddpm", "gaussian", seed, step, 4, 99.0, 1.0, batch, seconds) for seed in range(3)]
        write_store(tmp_path / store, rows)
    lines = methods_lines(tmp_path)
    text = "\n".join(lines)
    assert "Before: batch 32, lr 0.001, fp32, step 16000" in text and "after: batch 256, lr 0.003, bf16" in text
    # DDPM NFE 1: 51/53/55 -> 53.0 ± 1.2; after 62/63/64 -> 63.0 ± 0.6; per seed +11, +10, +9 -> +10.0 ± 0.6
    assert "| DDPM | 1 | 9.5 / 10.0 | 53.0 ± 1.2 | 63.0 ± 0.6 | +10.0 ± 0.6 | better |" in text
    # flow NFE 2: 62 x 3 against 61/62/66 -> +1.0 ± 1.5 (sd sqrt 7), a tie
    assert "| flow (line) | 2 | 9.5 / 10.0 | 62.0 ± 0.0 | 63.0 ± 1.5 | +1.0 ± 1.5 | tie |" in text
    assert "| 4 |" not in text  # NFE 4 is in one store only: not paired
    assert sum(line.startswith("|") for line in lines) == 2 + 4  # header and rule, 2 methods x 2 NFEs
    assert lines[1] == "## large: every method at the old runs' wall-clock, batch 256, lr 0.003, bf16"
    # the other pairings' stores are absent: their sections are left out, not empty
    assert sum(line.startswith("## ") for line in lines) == 1

    # the precision alone, at equal steps on another CPU: AFTER's runs against the fp32 store's, no minutes
    store, step = PAIRINGS[1].after
    assert PAIRINGS[1].before == AFTER and not PAIRINGS[1].wallclock and step == AFTER[1]
    rows = [store_row(p, q, seed, step, 1, s + 1 + 2 * seed, 0.5, 256, 1800.0, precision="fp32")
            for (p, q), values in after.items() for seed, s in enumerate(values)]
    write_store(tmp_path / store, rows)
    text = "\n".join(methods_lines(tmp_path))
    assert "## large: batch 256, lr 0.003, fp32 against batch 256, lr 0.003, bf16, at equal steps" in text
    # DDPM NFE 1: 62/63/64 -> 62/65/68 (+0, +2, +4: +2.0 ± 1.2), a tie; no minutes column
    assert "| DDPM | 1 | 63.0 ± 0.6 | 65.0 ± 1.7 | +2.0 ± 1.2 | tie |" in text
    assert "30.0" not in text and text.count("minutes before / after") == 1
