"""Report generators on hand-made rows: the CDDB report (settings chosen on validation and reported on test,
DDPM's bar its best NFE, verdicts from the paired differences) and the OGBench calibration's averaging."""

from __future__ import annotations

import csv
import json

import pytest

from bridgeplan.processes import make_process
from tests.reports import GENERATORS, report

cddb = report("cddb")

SEEDS = (0, 1, 2)
FIELDS = ["id", "experiment", "run_name", "maze", "process", "prior", "diffusion_steps", "seed", "step", "nfe",
          "episodes", "eval_seed", "score_minari", "score_minari_se", "success_rate", "plan_ms", "floor_minari",
          "execution", "multi_task", "sampler", "calls_per_episode", "network_calls_per_plan", "plan_kinematics_rms",
          "plan_dynamics_rms", "config", "code_version"]


def _row(experiment, process, prior, step, nfe, score, seed, sampler="", calls=None, execution="", maze="medium"):
    config = {"process": process.to_dict(), "prior": prior, "hold_share": 0.0}
    return {"experiment": experiment, "run_name": f"{process.name}-s{seed}", "maze": maze,
            "process": process.name, "prior": prior if process.uses_prior else "gaussian",
            "diffusion_steps": process.steps, "seed": seed, "step": step, "nfe": nfe, "episodes": 200,
            "eval_seed": seed, "score_minari": score + 0.1 * seed, "score_minari_se": 1.0, "success_rate": 0.5,
            "plan_ms": 2.0, "floor_minari": 30.0, "execution": execution, "multi_task": 0, "sampler": sampler,
            "calls_per_episode": nfe, "network_calls_per_plan": calls or nfe, "plan_kinematics_rms": 0.5,
            "plan_dynamics_rms": 0.25, "config": json.dumps(config), "code_version": "0.1.0+test"}


def write_rows(root):
    ddpm = make_process("ddpm", steps=16)
    bridge = make_process("bridge", steps=16, consistent=True)
    rows = []
    for seed in SEEDS:
        for step in (4000, 8000):
            rows += [_row("cddb-uncorrected", ddpm, "gaussian", step, 1, 50.0, seed),
                     _row("cddb-uncorrected", ddpm, "gaussian", step, 16, 70.0, seed),
                     _row("cddb-uncorrected", bridge, "line", step, 1, 60.0, seed),
                     _row("cddb-uncorrected", bridge, "line", step, 2, 62.0, seed)]
        rows += [_row("cddb-uncorrected-validation", bridge, "line", 8000, nfe, 61.0, seed) for nfe in (1, 2)]
        # validation prefers the small step, test the large one: the report must take validation's choice
        for sampler, validation, test in (("cddb-x0 dynamics=0.0001", 80.0, 65.0),
                                          ("cddb-x0 dynamics=0.0003", 70.0, 75.0)):
            for nfe in (1, 2):
                rows += [_row("cddb", bridge, "line", 8000, nfe, test, seed, sampler),
                         _row("cddb-validation", bridge, "line", 8000, nfe, validation + nfe, seed, sampler)]
        rows += [_row("cddb", bridge, "line", 8000, 1, 71.0, seed, "cddb-deep dynamics=0.0001", calls=3),
                 _row("cddb-validation", bridge, "line", 8000, 1, 60.0, seed, "cddb-deep dynamics=0.0001", calls=3)]
    _write(root / cddb.SOURCES[0] / "results.csv", rows)


def _write(path, rows):
    path.parent.mkdir(parents=True)
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows({"id": i, **r} for i, r in enumerate(rows))


def test_the_report_chooses_on_validation_and_judges_on_test(tmp_path):
    write_rows(tmp_path)
    text = GENERATORS["cddb"].render(tmp_path)
    lines = text.splitlines()
    # DDPM's bar is its best NFE (16) at each step; the uncorrected bridge at NFE <= 2 falls 8 short
    curve = next(line for line in lines if line.startswith("| 8000 |"))
    assert "70.1 ± 0.1 (16)" in curve and "no (-8.0 ± 0.0) at NFE 2" in curve
    # at NFE 2, validation chooses dynamics=0.0001 (bold) although dynamics=0.0003 scores higher on test
    nfe2 = [line for line in lines if line.startswith("| 2 |")]
    assert any("**cddb-x0 dynamics=0.0001**" in line and "| 65.1 ± 0.1 |" in line and "+3.0 ± 0.0" in line
               for line in nfe2)
    assert any("| cddb-x0 dynamics=0.0003 |" in line and "| 75.1 ± 0.1 |" in line and "yes (+5.0 ± 0.0)" in line
               for line in nfe2)
    # the deep correction's cost: 3 network-call equivalents per plan at NFE 1
    assert any("cddb-deep dynamics=0.0001" in line and "| 3 |" in line for line in lines if line.startswith("| 1 |"))
    # the goal per residual: each form and residual with its validation choice, judged on test
    goal = [line for line in lines if line.startswith("- ")]
    assert "- cddb-x0 dynamics: chosen on validation cddb-x0 dynamics=0.0001 at NFE 2: test 65.1 ± 0.1" in goal[1]
    assert goal[1].endswith("no (-5.0 ± 0.0)")
    assert goal[2].startswith("- cddb-deep dynamics: chosen on validation cddb-deep dynamics=0.0001 at NFE 1")
    assert goal[2].endswith("yes (+1.0 ± 0.0)")
    assert goal[0].startswith("- uncorrected: chosen on validation uncorrected at NFE 1")
    # the README's block: the same verdicts, each naming its method, snapshot and seeds
    block = cddb.block(tmp_path).splitlines()
    assert block[1] == "- medium, tracked, bridge (line; consistent=True), step 8000, 3 training seeds, " + goal[1][2:]
    # and what the corrections themselves change: 5 settings, from +3 (x0 1e-4 at NFE 2: 65 - 62) to +15
    assert block[-1] == (
        "- what a correction changes, against its uncorrected sampler at the same NFE (test episodes, paired per "
        "seed; 5 settings over every maze and execution): from +3.0 ± 0.0 (medium, tracked, bridge (line; "
        "consistent=True) at NFE 2, cddb-x0 dynamics=0.0001) to +15.0 ± 0.0 (medium, tracked, bridge (line; "
        "consistent=True) at NFE 1, cddb-x0 dynamics=0.0003); beyond two standard errors: 5")


def test_each_maze_and_execution_is_judged_against_its_own_ddpm(tmp_path):
    """Large's rows, tracked and pursued in one folder: two parts after medium's, each bridge against the DDPM of
    its own execution (the pursued DDPM is 20 higher: a bridge that would reach the tracked bar does not)."""
    write_rows(tmp_path)
    ddpm = make_process("ddpm", steps=16)
    bridge = make_process("bridge", steps=16, consistent=True)
    rows = []
    for seed in SEEDS:
        for execution, ddpm_score in (("", 70.0), ("pursuit1.5", 90.0)):
            rows += [_row("u", ddpm, "gaussian", 8000, 2, ddpm_score, seed, execution=execution, maze="large"),
                     _row("u", bridge, "line", 8000, 1, 80.0, seed, execution=execution, maze="large"),
                     _row("u-validation", bridge, "line", 8000, 1, 80.0, seed, execution=execution, maze="large")]
    _write(tmp_path / "large-cddb" / "results.csv", rows)
    text = GENERATORS["cddb"].render(tmp_path)
    titles = [line for line in text.splitlines() if line.startswith("## ")]
    assert titles == ["## medium, tracked", "## large, tracked", "## large, pursued (lookahead 1.5)"]
    block = cddb.block(tmp_path).splitlines()
    large = [line for line in block if line.startswith("- large")]
    assert large[0] == ("- large, tracked, bridge (line; consistent=True), step 8000, 3 training seeds, uncorrected: "
                        "chosen on validation uncorrected at NFE 1: test 80.1 ± 0.1, reaches DDPM's best "
                        "(70.1 ± 0.1 at NFE 2): yes (+10.0 ± 0.0)")
    assert large[1].startswith("- large, pursued (lookahead 1.5), bridge")
    assert large[1].endswith("(90.1 ± 0.1 at NFE 2): no (-10.0 ± 0.0)")


def test_ogbench_calibration_averages_the_last_three_evaluations_per_seed(tmp_path):
    """GCBC as OGBench averages it: per training seed the mean of its last 3 evaluations, then over seeds."""
    oc = report("ogbench-calibration")

    def row(seed, step, rate, **extra):
        tasks = {str(i): {"task_id": i, "success_rate": rate} for i in range(1, 6)}
        return {"run": f"gcbc-s{seed}", "step": step, "code_version": "v", "maze": "large",
                "env_id": "pointmaze-large-v0", "episodes_per_task": 50, "seed": 0, "success_rate": rate,
                "tasks": tasks, **extra}

    (tmp_path / oc.ORACLE).mkdir()
    (tmp_path / oc.ORACLE / "large.json").write_text(json.dumps(row(0, 0, 0.9)))
    (tmp_path / oc.GCBC).mkdir()
    for seed, rates in ((0, (0.9, 0.1, 0.2, 0.3)), (1, (0.0, 0.3, 0.4, 0.5))):  # the first snapshot is left out
        for step, rate in zip((1, 2, 3, 4), rates):
            (tmp_path / oc.GCBC / f"s{seed}-{step}.json").write_text(json.dumps(
                row(seed, step, rate, dataset="pointmaze-large-navigate-v0", train_seed=seed)))
    stitch = tmp_path / f"{oc.GCBC}-medium-stitch"  # another dataset's study writes a folder of its own
    stitch.mkdir()
    for step, rate in zip((1, 2, 3), (0.2, 0.25, 0.3)):
        (stitch / f"s0-{step}.json").write_text(json.dumps(
            row(0, step, rate, dataset="pointmaze-medium-stitch-v0", train_seed=0)))
    text = oc.render(tmp_path)
    # seed 0: mean(10, 20, 30) = 20; seed 1: mean(30, 40, 50) = 40; over seeds 30 ± 10
    assert "**30.0 ± 10.0**; OGBench's published GCBC: 29" in text
    assert "| pointmaze-large-v0 | 50 | 90 | 90 | 90 | 90 | 90 | 90.0 | v |" in text
    assert "### pointmaze-medium-stitch-v0" in text and "**25.0**; OGBench's published GCBC: 23" in text


def _hierarchy_row(seed, eval_seed, low, nfe_low, score, coarse, multi=False):
    level = {"method": "flow (line)", "nfe": 4, "horizon": 32, "stride": 24, "step": 8000, "subgoal_every": 0,
             "config": {"seed": seed}}
    low_level = {"method": low, "nfe": nfe_low, "horizon": 16, "stride": 8, "step": 8000, "subgoal_every": 3,
                 "config": {"seed": seed}}
    def scored(minari, success):
        return {"score": {"minari": {"mean": minari, "se": 1.0}}, "success_rate": {"mean": success, "se": 0.01}}
    return {"kind": "hierarchy", "maze": "large", "episodes": 200, "seed": eval_seed, "multi_task": multi,
            "high": level, "low": low_level, **scored(score, 0.9), "high_alone": scored(coarse, 0.7),
            "floor_line": scored(40.0, 0.3), "calls_per_episode": 4 + 34 * nfe_low,
            "execution": {"replan_every": 24, "controller": "pursuit", "lookahead": 1.5},
            "decision_ms_batch1": {"p50": 1.5, "p95": 4.0}, "environment": {"code_version": "0.1.0+test"}}


def test_hierarchy_report_chooses_on_validation_and_pairs_with_the_coarse_plans(tmp_path):
    hierarchy = report("hierarchy")

    folder = tmp_path / "large-hierarchy"
    for nfe_low, test_score, validation_score in ((1, 90.0, 80.0), (4, 95.0, 70.0)):
        for seed in SEEDS:
            for eval_seed, score in ((seed, test_score + seed), (1000 + seed, validation_score)):
                out = folder / f"flow-nfe{nfe_low}" / f"seed{eval_seed}.json"
                out.parent.mkdir(parents=True, exist_ok=True)
                out.write_text(json.dumps(_hierarchy_row(seed, eval_seed, "flow (coarse)", nfe_low, score,
                                                         coarse=80.0 + 2 * seed)))
    (tmp_path / "expert-on-eval-tasks.json").write_text(json.dumps({"rows": [
        {"maze": "large", "multi_task": False, "seed": s, "score_minari": 104.0} for s in SEEDS]}))
    rows = hierarchy.read_rows(tmp_path, "large")
    chosen = hierarchy.chosen_settings(rows, False)
    family = "flow (line) H32k24 -> flow (coarse) H16k8"
    assert list(chosen) == [family] and "NFE 1 (H16k8" in chosen[family]  # validation's 80 > 70
    block = hierarchy.block(tmp_path)
    # test 90, 91, 92 (91.0 ± 0.6) against the coarse plans' 80, 82, 84: differences 10, 9, 8 -> 9.0 ± 0.6, better
    assert "91.0 ± 0.6 (success 0.90)" in block and "+9.0 ± 0.6 (better)" in block
    assert "missed by 0.08 success and 13.0 points" in block
    text = GENERATORS["hierarchy"].render(tmp_path)
    assert "**91.0 ± 0.6**" in text and "The expert on the same test episodes: 104.0 ± 0.0" in text


def test_hierarchy_report_pairs_a_replanned_high_level_with_itself_alone(tmp_path):
    hierarchy = report("hierarchy")

    for seed in SEEDS:
        for eval_seed in (seed, 1000 + seed):
            row = _hierarchy_row(seed, eval_seed, "flow (coarse)", 1, 90.0 + seed, coarse=60.0)
            row["execution"]["replan_high_every"] = 96
            row["high"].update(process="flow", nfe=4)
            out = tmp_path / "large-hierarchy" / "replanned" / f"single-seed{eval_seed}.json"
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(json.dumps(row))
            alone = {"method": "flow (line)", "process": "flow", "nfe": 4, "horizon": 32, "stride": 24,
                     "seed": eval_seed, "multi_task": False, "config": {"seed": seed},
                     "execution": {"replan_every": 96, "controller": "pursuit", "lookahead": 1.5},
                     "score": {"minari": {"mean": 80.0}}, "success_rate": {"mean": 0.8}, "calls_per_episode": 36,
                     "decision_ms_batch1": {"p50": 2.0, "p95": 3.0}}
            out = tmp_path / "large-hierarchy-flat" / "replan96" / f"single-seed{eval_seed}.json"
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(json.dumps(alone))
    (tmp_path / "expert-on-eval-tasks.json").write_text(json.dumps({"rows": []}))
    block = hierarchy.block(tmp_path)
    # 90, 91, 92 against the high level alone replanned every 96 (80 each): +11.0 ± 0.6, better
    assert "minus its high level alone, replanned as often, +11.0 ± 0.6 (better)" in block
    text = GENERATORS["hierarchy"].render(tmp_path)
    assert "| flow (line) NFE 4 (H32k24) alone; replan 96, pursuit 1.5 | 80.0 ± 0.0 | 80.0 ± 0.0 | 0.80 |" in text


def test_hierarchy_report_reads_the_graph_as_a_high_level(tmp_path):
    """A `graph --low` row: the graph has no training seed (its low level's counts), no span for a line
    floor ('-'), and a family of its own; the goal is judged on its test episodes."""
    hierarchy = report("hierarchy")

    for seed in SEEDS:
        for eval_seed in (seed, 1000 + seed):
            row = _hierarchy_row(seed, eval_seed, "flow (coarse)", 1, 104.5 + seed, coarse=85.0)
            row["high"] = {"run": "dataset graph", "step": 0, "method": "dataset graph", "process": "graph", "nfe": 0,
                           "horizon": 68, "stride": 12, "subgoal_every": None,
                           "graph": {"keep": 10, "radius": 0.2, "nodes": 100}}
            row["success_rate"]["mean"] = 0.99
            del row["floor_line"]
            out = tmp_path / "large-hierarchy" / "graph" / f"single-seed{eval_seed}.json"
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(json.dumps(row))
    (tmp_path / "expert-on-eval-tasks.json").write_text(json.dumps({"rows": []}))
    rows = hierarchy.read_rows(tmp_path, "large")
    assert list(hierarchy.chosen_settings(rows, False)) == ["dataset graph -> flow (coarse) H16k8"]
    block = hierarchy.block(tmp_path)
    assert block.startswith("- large single-task, dataset graph -> flow (coarse) H16k8: 105.5 ± 0.6 (success 0.99)")
    assert "+20.5 ± 0.6 (better)" in block and block.endswith("goal (success >= 0.98, Minari >= 104): met")
    text = GENERATORS["hierarchy"].render(tmp_path)
    assert ("| **dataset graph (keep 10, radius 0.2; every 12) -> flow (coarse) NFE 1 (H16k8, subgoal every 3); "
            "replan 24, pursuit 1.5** | 105.5 ± 0.6 | **105.5 ± 0.6** | 0.99 | 85.0 ± 0.0 | 0.70 | +20.5 ± 0.6 "
            "(better) | - |") in text
    assert "Training seeds 0, 1, 2;" in text


def test_hierarchy_report_has_a_stitching_section_with_its_own_flat_planners(tmp_path):
    """docs/results/large-stitch-hierarchy{,-flat}: a section of its own, whose flat planner is the best of its
    -flat folder on validation (trained on the same pieces), paired on test."""
    hierarchy = report("hierarchy")

    for seed in SEEDS:
        for eval_seed in (seed, 1000 + seed):
            row = _hierarchy_row(seed, eval_seed, "flow (coarse)", 1, 100.0 + seed, coarse=85.0)
            out = tmp_path / "large-stitch-hierarchy" / "graph" / f"single-seed{eval_seed}.json"
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(json.dumps(row))
            for every, score in ((48, 40.0), (96, 60.0 if eval_seed < 1000 else 30.0)):
                flat = {"method": "DDPM", "process": "ddpm", "nfe": 16, "horizon": 24, "stride": 8, "seed": eval_seed,
                        "multi_task": False, "config": {"seed": seed},
                        "execution": {"replan_every": every, "controller": "pursuit", "lookahead": 1.5},
                        "score": {"minari": {"mean": score + seed}}, "success_rate": {"mean": 0.4},
                        "calls_per_episode": 272, "decision_ms_batch1": {"p50": 20.0, "p95": 30.0}}
                out = tmp_path / "large-stitch-hierarchy-flat" / f"r{every}" / f"single-seed{eval_seed}.json"
                out.parent.mkdir(parents=True, exist_ok=True)
                out.write_text(json.dumps(flat))
    (tmp_path / "expert-on-eval-tasks.json").write_text(json.dumps({"rows": []}))
    block = hierarchy.block(tmp_path)
    # replan 48 wins on validation (40 > 30) though 96 is higher on test: 100, 101, 102 minus 40, 41, 42
    assert block.startswith("- large from 200-step pieces (stitching) single-task, flow (line) H32k24 -> ")
    assert "minus the best flat planner (DDPM NFE 16 (H24k8) alone; replan 48, pursuit 1.5) +60.0 ± 0.0" in block
    text = GENERATORS["hierarchy"].render(tmp_path)
    assert "## large from 200-step pieces (stitching)" in text and "## large\n" not in text
    assert "Flat planners trained on the same pieces, replanned from the current state" in text


def test_ogbench_planners_reads_stitch_folders_and_the_graph_as_one_graph(tmp_path):
    """The dataset graph's rows (no training seed) in a stitch folder: a section of their own, judged on their one
    value; a graph with a low level counts its low level's training seeds."""
    op = report("ogbench-planners")

    def row(seed, rate, low_seed=None):
        tasks = {str(i): {"success_rate": rate} for i in range(1, 6)}
        r = {"kind": "graph", "method": "dataset graph", "nfe": 0, "seed": seed, "success_rate": rate,
             "tasks": tasks, "step": 0, "decision_ms_batch1": {"p50": 200.0},
             "execution": {"controller": "pursuit", "lookahead": 2.0, "replan_every": None},
             "graph": {"keep": 10, "radius": 0.5}, "environment": {"code_version": "v"}, "config": {}}
        if low_seed is not None:
            r.update(method="dataset graph -> flow (coarse) H16k4", nfe=1, low={"seed": low_seed}, step=4000,
                     config={"low": {"seed": low_seed}})
            r["execution"]["replan_every"] = 12
        return r

    folder = tmp_path / op.folder("large", "stitch")
    for name, seed, rate, low in (("g", 0, 0.96, None), ("g", 1000, 0.98, None), ("l0", 0, 0.9, 0),
                                  ("l1", 0, 0.8, 1), ("l0", 1000, 0.9, 0), ("l1", 1000, 0.7, 1)):
        (folder / f"{name}").mkdir(parents=True, exist_ok=True)
        (folder / name / f"seed{seed}.json").write_text(json.dumps(row(seed, rate, low)))
    text = op.render(tmp_path)
    assert "## pointmaze-large-stitch-v0" in text and "## pointmaze-large-navigate-v0" not in text
    assert "Training seeds 0, 1; step 4000;" in text
    assert "published stitch success: GCBC 7, QRL 84, CompDiffuser 100" in text
    lines = op.block(tmp_path).splitlines()
    assert lines[0] == ("- pointmaze-large-stitch-v0, dataset graph (keep 10, radius 0.5), no network, pursuit 2 "
                        "(chosen on validation): 96.0% one graph, no training; above: GCBC 7: yes, QRL 84: yes, "
                        "CompDiffuser 100: no (-4.0)")
    assert lines[1].startswith("- pointmaze-large-stitch-v0, dataset graph -> flow (coarse) H16k4 (graph keep 10, "
                               "radius 0.5), NFE 1, pursuit 2, replan 12 (chosen on validation): 85.0 ± 5.0% over 2 "
                               "training seeds")


def test_the_reports_read_every_evaluation_json_in_one_form(tmp_path):
    """The expert and the oracle rows of ``bridgeplan oracle`` (their score under ``score``, one JSON of ``rows``)
    read as the committed files (``reference expert-on-tasks``'s flat rows); every command's evaluation JSON (an
    EvalResult's, an oracle file's one row, an earlier flat ``gcbc eval`` row) reads with its code version on top."""
    from bridgeplan.analysis.load import read_evaluation
    from bridgeplan.errors import BridgeplanError

    headline = report("headline")
    (tmp_path / headline.EXPERT).write_text(json.dumps({"rows": [
        {"maze": "umaze", "multi_task": False, "seed": 0, "score_minari": 97.0},
        {"maze": "umaze", "multi_task": False, "seed": 1, "score": {"minari": {"mean": 99.0, "se": 1.0}}}]}))
    assert headline.expert_scores(tmp_path) == {("umaze", False): [97.0, 99.0]}
    row = {"maze": "medium", "env_id": "pointmaze-medium-v0", "success_rate": 0.9}
    files = {"flat": {**row, "code_version": "v"}, "oracle": {"code_version": "v", "rows": [row]},
             "result": {**row, "environment": {"code_version": "v", "cpu": "c"}},
             "two": {"code_version": "v", "rows": [row, row]}}
    for name, d in files.items():
        (tmp_path / f"{name}.json").write_text(json.dumps(d))
    assert read_evaluation(tmp_path / "flat.json") == read_evaluation(tmp_path / "oracle.json") == {
        **row, "code_version": "v"}
    assert read_evaluation(tmp_path / "result.json") == {**files["result"], "code_version": "v"}
    with pytest.raises(BridgeplanError, match="2 oracle rows"):
        read_evaluation(tmp_path / "two.json")


def _bench(device, latency, throughput, limits=None):
    machine = {"device": device, "torch": "2", "code_version": "0.1.0+test", "processor": "x86_64", "cpu": "CPU",
               "cpu_count": 2} | ({"gpu": "GPU X"} if device == "cuda" else {})
    rows = [{"preset": "p", "maze": "umaze", "horizon": 128, "stride": 1, "batch": b, "grad_accum": 1,
             "precision": prec, "implementation": "bridgeplan", "step_ms": 1000 * b / w, "windows_per_s": w,
             "gflops": g, "limit_gflops": {"matmul": (limits or {}).get(prec, 1.0), "conv": 1.0}, "threads": t,
             "busy_cores": busy}
            for b, prec, w, g, t, busy in throughput]
    return {"machine": machine, "bench": {"repeats": 3, "nfes": [1]}, "throughput": rows,
            "latency": [{"preset": "p", "method": "m", "batch": b, "nfe": n, "plan_ms": ms} for b, n, ms in latency]}


def _eval(nfe, episodes, batch, score, ms):
    return {"nfe": nfe, "episodes": episodes, "batch_size": batch, "diffusion_steps": 256, "horizon": 256,
            "maze": "medium", "step": 1000, "train_seconds": 100.0, "score": {"minari": {"mean": score, "se": 1.0}},
            "success_rate": {"mean": 0.5}, "plan_ms_per_plan": ms, "floor_line": {"score": {"minari": {"mean": 30.0}}},
            "config": {"preset": "diffuser", "horizon": 256, "stride": 1, "batch_size": 32, "grad_accum": 2,
                       "precision": "fp32", "dataset": "medium-1000000-v2"}}


def test_gpu_report_sets_each_gpu_figure_beside_the_cpu_one(tmp_path):
    """Speed-ups are CPU over GPU time of the same (preset, method, batch, NFE); CPU figures come from the first bench
    in name order that has them, its quiet one-thread rows only; the batch-1 evaluation times a plan, it scores
    nothing; the README's block names the run's best fraction of the bf16 matmul."""
    gpu = report("gpu")

    folder = tmp_path / "gpu"
    (folder / "cpu").mkdir(parents=True)
    (folder / "cpu-more").mkdir()
    (folder / "bench.json").write_text(json.dumps(_bench(
        "cuda", [(1, 1, 5.0), (1024, 1, 10.0), (1024, 64, 400.0)],
        [(1024, "fp32", 20000.0, 30000.0, 16, 0), (1024, "bf16", 25000.0, 40000.0, 16, 0)],
        limits={"fp32": 50000.0, "bf16": 800000.0})))
    (folder / "cpu" / "bench.json").write_text(json.dumps(_bench(
        "cpu", [(1, 1, 2.0), (1024, 1, 3000.0)], [(1024, "fp32", 900.0, 5.0, 2, 0), (1024, "fp32", 800.0, 5.0, 1, 1),
                                                  (1024, "fp32", 1000.0, 5.0, 1, 0)])))
    (folder / "cpu-more" / "bench.json").write_text(json.dumps(_bench("cpu", [(1, 1, 99.0), (1024, 64, 8000.0)], [])))
    for name, e in {"eval-nfe1": _eval(1, 200, 200, 10.0, 2.0), "eval-nfe256": _eval(256, 200, 200, 27.0, 11.0),
                    "eval-nfe256-batch1": _eval(256, 5, 1, 99.0, 1600.0)}.items():
        (folder / f"{name}.json").write_text(json.dumps(e))

    text = gpu.render(tmp_path)
    assert "| p | m | 1 | 1 | 5.00 | 2.0 | 0.4x |" in text  # the CPU is faster at batch 1: from cpu/, not cpu-more/
    assert "| p | m | 1024 | 1 | 10.00 | 3000.0 | 300x |" in text
    assert "| p | m | 1024 | 64 | 400.00 | 8000.0 | 20x |" in text  # only cpu-more/ timed it
    assert "| 20,000 | 30.0 | 0.037 | 1,000 |" in text  # the quiet one-thread CPU row, the bf16 limit's fraction
    assert "| 25,000 | 40.0 | 0.050 | not timed |" in text
    assert "| 1 | 200 | 10.0 ± 1.0 |" in text and "| 256 | 200 | 27.0 ± 1.0 |" in text and "99.0" not in text
    assert "the medium run (256 states, NFE 256) 1600 ms against 9.9 s" in text
    block = gpu.block(tmp_path)
    assert "40.0 TFLOP/s at best" in block and "5% of the bf16 matmul rate" in block
    assert "10.0 ± 1.0 at NFE 1, 27.0 ± 1.0 at NFE 256 (200 episodes)" in block


def test_demo_report_gives_each_series_lowest_and_highest_over_seeds_at_the_last_snapshot(tmp_path):
    """The README's expected range: per series, min and max over the training seeds of the last snapshot's score and
    success (earlier snapshots and validation rows left out), and the line alone's range beneath."""
    demo = report("demo")
    ddpm, bridge = make_process("ddpm", steps=16), make_process("bridge", steps=16)
    rows = []
    for seed, (d1, b15) in enumerate([(-3.0, 60.2), (8.6, 66.8), (1.0, 63.0)]):
        rows += [_row("demo", ddpm, "gaussian", 1500, 1, d1, seed), _row("demo", bridge, "line", 1500, 15, b15, seed),
                 _row("demo", ddpm, "gaussian", 1000, 1, 99.0, seed),  # an earlier snapshot
                 _row("demo-validation", ddpm, "gaussian", 1500, 1, -50.0, seed)]
    _write(tmp_path / "demo" / "results.csv", rows)
    text = demo.block(tmp_path)
    # _row adds 0.1 * seed to each score
    assert "| DDPM N=16 NFE=1 | -3 to 9 | 0.50 |" in text
    assert "| bridge (line) N=16 NFE=15 | 60 to 67 | 0.50 |" in text
    assert "| the line alone (no network) | 30 |  |" in text
    assert "S = 0, 1, 2 (step 1500, 200 test episodes each" in text


def test_the_onestep_report_judges_each_one_step_method_against_ddpms_bar_chosen_on_validation(tmp_path):
    """DDPM's bar is its NFE chosen on validation (4, though 16 scores higher on test); the mean flow at NFE 1
    reaches it at the last step, the shortcut at NFE 2 does not; the pursued rows are a part of their own."""
    onestep = report("onestep")
    ddpm, meanflow = make_process("ddpm", steps=16), make_process("meanflow", steps=16)
    shortcut = make_process("shortcut", steps=16)
    rows = []
    for seed in SEEDS:
        for step in (4000, 8000):
            rows += [_row("onestep-tracked", ddpm, "gaussian", step, 4, 70.0, seed),
                     _row("onestep-tracked", ddpm, "gaussian", step, 16, 80.0, seed),
                     _row("onestep-tracked", meanflow, "line", step, 1, 60.0 + step / 800, seed),
                     _row("onestep-tracked", shortcut, "line", step, 2, 50.0, seed)]
        rows += [_row("onestep-tracked-validation", ddpm, "gaussian", 8000, 4, 75.0, seed),
                 _row("onestep-tracked-validation", ddpm, "gaussian", 8000, 16, 72.0, seed),
                 _row("onestep-pursued", ddpm, "gaussian", 8000, 16, 90.0, seed, execution="pursuit1.5"),
                 _row("onestep-pursued", meanflow, "line", 8000, 1, 70.0, seed, execution="pursuit1.5")]
    _write(tmp_path / onestep.SOURCES[0] / "results.csv", rows)
    text = GENERATORS["onestep"].render(tmp_path)
    sections = text.split("## ")
    assert sections[1].startswith("medium, tracked, single-task") and sections[2].startswith("medium, pursued")
    tracked = sections[1].splitlines()
    assert "| DDPM's best | 4 / 4 | 70.1 ± 0.1 | 70.1 ± 0.1 |  |" in tracked
    assert "| mean flow (line) | 1 | 65.1 ± 0.1 | 70.1 ± 0.1 | yes (+0.0 ± 0.0) |" in tracked
    assert "| shortcut (line) | 2 | 50.1 ± 0.1 | 50.1 ± 0.1 | no (-20.0 ± 0.0) |" in tracked
    pursued = sections[2].splitlines()
    assert "| DDPM's best | 16 | 90.1 ± 0.1 |  |" in pursued
    assert "| mean flow (line) | 1 | 70.1 ± 0.1 | no (-20.0 ± 0.0) |" in pursued


def test_the_onestep_report_sets_the_bridges_parametrizations_against_ddpm_and_the_default_bridge(tmp_path):
    """medium-v2-curves' tracked single-task rows: DDPM's bar, and each parametrization at NFE 1 against it and, paired
    per seed, against I2SB's bridge at the same NFE (the default's own row has no difference); Multi2D rows and a
    replanned part are not this section's."""
    onestep = report("onestep")
    ddpm, bridge = make_process("ddpm", steps=16), make_process("bridge", steps=16)
    ddbm = make_process("bridge", steps=16, predict="ddbm", weighting="ddbm")
    rows = []
    for seed in SEEDS:
        rows += [_row("nfe-curves", ddpm, "gaussian", 8000, 2, 80.0, seed),
                 _row("nfe-curves", bridge, "line", 8000, 1, 70.0, seed),
                 _row("nfe-curves", ddbm, "line", 8000, 1, 75.0 + seed, seed),
                 _row("closed-loop", ddbm, "line", 8000, 1, 13.0, seed, execution="replan32")]
    _write(tmp_path / onestep.PARAMETRIZATIONS_SOURCES[0] / "results.csv", rows)
    text = onestep.render(tmp_path).split("## The bridge's parametrizations (medium, tracked, single-task)")[1]
    lines = text.split("## ")[0].splitlines()
    assert "| DDPM's best | 2 | 80.1 ± 0.1 |  |  |" in lines
    assert "| bridge (line) | 1 | 70.1 ± 0.1 | no (-10.0 ± 0.0) |  |" in lines
    # scores 75.0, 76.1, 77.2 (seeds 0-2): 5, 6, 7 above the default bridge and 5, 4, 3 below DDPM's bar
    assert "| bridge (line; predict=ddbm; weighting=ddbm) | 1 | 76.1 ± 0.6 | no (-4.0 ± 0.6) | +6.0 ± 0.6 |" in lines
    assert "13.1" not in text.split("## ")[0]  # the replanned rows


def test_the_onestep_report_times_the_decision_at_batch_1_against_2_ms(tmp_path):
    """The bench's batch-1 rows (batch 64 left out) against the goal; the machine's load written beside them."""
    onestep = report("onestep")
    assert "Not measured yet: `bridgeplan bench" in onestep.render(tmp_path)
    bench = {"bench": {"repeats": 50}, "machine": {"code_version": "0.1.0+abc", "device": "cpu",
                                                   "cpu": "AMD EPYC (avx2)", "cpu_count": 2,
                                                   "torch_threads": 1, "load_1min_start": 0.5, "load_1min_end": 1.25},
             "latency": [{"method": "mean flow (line)", "batch": 1, "nfe": 1, "plan_ms": 1.734, "maze": "medium",
                          "horizon": 32, "stride": 8},
                         {"method": "DDPM [ancestral]", "batch": 1, "nfe": 2, "plan_ms": 3.01},
                         {"method": "mean flow (line)", "batch": 64, "nfe": 1, "plan_ms": 1.0}]}
    (tmp_path / onestep.LATENCY).mkdir()
    (tmp_path / onestep.LATENCY / "bench.json").write_text(json.dumps(bench))
    lines = onestep.render(tmp_path).splitlines()
    # the row of a bench that names its plans' shape, and one of a bench that did not (umaze's, then)
    assert "| medium, 32 x 8 | mean flow (line) | 1 | 1.73 | yes |" in lines
    assert "| umaze, 128 x 1 | DDPM [ancestral] | 2 | 3.01 | no |" in lines
    assert sum("| mean flow (line) |" in line for line in lines) == 1
    assert any("load average was 0.5 at the start and 1.2 at the end" in line for line in lines)
    assert any("cpu (AMD EPYC (avx2), 2 cores, 1 torch thread)" in line for line in lines)


def test_the_manipulation_report_splits_test_from_validation_and_averages_over_seeds(tmp_path):
    """Each dataset's rows by its folder; each method's by the file (GCBC, GCIQL) or folder (a planner's) they are in;
    the validation tasks (ids above 5) apart from the test tasks; mean ± SE over training seeds; each dataset's
    published numbers beside its test rows."""
    mc = report("manipulation")
    assert "No rows yet" in mc.render(tmp_path)
    folder = tmp_path / mc.folder("cube-single")

    def write(path, rate, tasks=(1, 2, 3, 4, 5), seed=0, step=20000, replan=None, graph=None):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"success_rate": rate, "train_seed": seed, "seed": 0, "step": step,
                                    "execution": {"replan_every": replan},
                                    "tasks": {str(t): {"success_rate": rate} for t in tasks},
                                    **({"graph": graph} if graph else {})}))

    write(folder / "gcbc-s0-step20000-seed0.json", 0.04)
    write(folder / "gcbc-s1-step20000-seed0.json", 0.08, seed=1)
    write(folder / "ddpm-s0" / "nfe16-replan8-seed0.json", 0.5)
    write(folder / "ddpm-s0" / "nfe16-replan8-seed1000-tasks678910.json", 0.3, tasks=(6, 7, 8, 9, 10))
    # earlier snapshots: not in the main table; seed 0 has its last three (OGBench's average), seed 1 not
    write(folder / "gcbc-s0-step10000-seed0.json", 0.10, step=10000)
    write(folder / "gcbc-s0-step15000-seed0.json", 0.16, step=15000)
    write(folder / "gcbc-s1-step15000-seed0.json", 0.20, seed=1, step=15000)
    lines = mc.render(tmp_path).splitlines()
    assert "| gcbc | test | 2 | 6.0 ± 2.0 | 6 (8 seeds, 1 M steps) | - |" in lines
    assert "| ddpm | test | 1 | 50.0 | - | - |" in lines
    assert "| ddpm | validation (tasks 6-10) | 1 | 30.0 |  | - |" in lines
    assert "| method | 10 k steps | 15 k steps | 20 k steps | OGBench's average (last 3) |" in lines
    assert "| gcbc | 10.0 (1) | 18.0 ± 2.0 (2) | 6.0 ± 2.0 (2) | 10.0 (1) |" in lines
    # the README's table: per dataset its best planner (not a peer) on the test tasks, in words, beside GCIQL's
    assert mc.block(tmp_path).splitlines()[2:] == [
        "| cube-single-play-v0 | DDPM planner (cpu-small, 20 k steps, NFE 16, replanned every 8 steps) | 50.0 (one "
        "run) | not trained here | 68 (8 seeds, 1 M steps) |"]
    # a second dataset: its own section, its own published numbers, the graph named by its folder and replanning
    write(tmp_path / mc.folder("puzzle-3x3") / "gciql-s0-step20000-seed0.json", 0.9)
    write(tmp_path / mc.folder("puzzle-3x3") / "graph-keep10-r1.5" / "track-replan50-seed0.json", 0.7, step=0,
          replan=50)
    lines = mc.render(tmp_path).splitlines()
    assert lines.index("## cube-single-play-v0") < lines.index("## puzzle-3x3-play-v0")
    assert ("OGBench published: GCBC 2, GCIQL 95 (8 seeds, 1 M steps)."
            in lines[lines.index("## puzzle-3x3-play-v0") + 2])
    assert lines[lines.index("## puzzle-3x3-play-v0"):].count(
        "| gciql | test | 1 | 90.0 | 95 (8 seeds, 1 M steps) | - |")
    assert mc.block(tmp_path).splitlines()[3:] == [
        "| puzzle-3x3-play-v0 | the dataset graph (no network: every 10th state, radius 1.5, replanned every 50 steps) "
        "| 70.0 (one run) | 90.0 (one run) | 95 (8 seeds, 1 M steps) |"]
    # a dataset without GCIQL rows: its published number alone
    write(tmp_path / mc.folder("scene") / "graph-keep5-r1" / "track-replan50-seed0.json", 0.5, step=0, replan=50)
    assert ("| scene-play-v0 | the dataset graph (no network: every 5th state, radius 1, replanned every 50 steps) | "
            "50.0 (one run) | not trained here | 51 (8 seeds, 1 M steps) |") in mc.block(tmp_path).splitlines()
    # the objects apart: named so
    write(tmp_path / mc.folder("cube-double") / "graph-keep5-r1-objects" / "track-replan150-seed0.json", 0.2, step=0,
          replan=150)
    assert ("| cube-double-play-v0 | the dataset graph (no network: every 5th state, radius 1, one graph per cube, "
            "replanned every 150 steps) | 20.0 (one run) |") in mc.block(tmp_path)
    # on a puzzle, the presses solved (its graph counts buttons)
    write(tmp_path / mc.folder("puzzle-4x4") / "graph-keep5-r1-objects" / "track-replan5-seed0.json", 1.0, step=0,
          replan=5, graph={"buttons": 16})
    assert ("| puzzle-4x4-play-v0 | the dataset graph (no network: every 5th state, radius 1, the buttons' presses "
            "solved (Lights Out), the arm's way to each searched, replanned every 5 steps) | 100.0 (one run) |"
            ) in mc.block(tmp_path)
    # on scene, its parts' steps (its graph counts paths per part)
    write(tmp_path / mc.folder("scene") / "graph-keep5-r1-objects" / "track-replan50-seed0.json", 0.6, step=0,
          replan=50, graph={"paths_per_part": [1, 1, 1, 1, 1]})
    assert ("| scene-play-v0 | the dataset graph (no network: every 5th state, radius 1, one graph per part (cube, "
            "buttons, drawer, window), their steps in order, replanned every 50 steps) | 60.0 (one run) |"
            ) in mc.block(tmp_path)
    write(tmp_path / mc.folder("scene") / "graph-keep5-r1-objects-afterstep25" / "track-replan150-afterstep25-seed0"
          ".json", 0.7, step=0, replan=150, graph={"paths_per_part": [1, 1, 1, 1, 1]})
    assert ("their steps in order, replanned every 150 steps and 25 steps after a path's first step ends) | 70.0 "
            "(one run) |") in mc.block(tmp_path)
    # rows on the recipe's data generated again elsewhere: apart from the same folder's rows on the first data, their
    # data's sha256 beside them; the hand's opening measured named so
    def regenerated(folder, rate, sha, seed=0):
        path = tmp_path / mc.folder("scene") / folder / f"track-replan150-afterstep25-seed{seed}.json"
        write(path, rate, step=0, replan=150, graph={"paths_per_part": [1, 1, 1, 1, 1]})
        path.write_text(json.dumps({**json.loads(path.read_text()), "seed": seed, "config": {
            "dataset_identity": f"scene-play-v0.npz (scene-play-v0, 1001000 transitions, sha256 {sha})"}}))

    regenerated("graph-keep5-r1-objects-afterstep25", 0.7, "8d47fbab505381fa", seed=1)
    for seed, (without, hand) in enumerate(((0.5, 0.8), (0.4, 0.8), (0.6, 0.8))):
        regenerated("regenerated-data/graph-keep5-r1-objects-afterstep25", without, "56abd1befc8f130a", seed)
        regenerated("regenerated-data/graph-keep5-r1-objects-hand-afterstep25", hand, "56abd1befc8f130a", seed)
    lines = mc.render(tmp_path).splitlines()
    assert "| graph-keep5-r1-objects-afterstep25 | test | 2 | 70.0 ± 0.0 | - | 8d47fbab505381fa |" in lines
    assert ("| regenerated-data/graph-keep5-r1-objects-afterstep25 | test | 3 | 50.0 ± 5.8 | - | 56abd1befc8f130a |"
            in lines)
    # the hand against the same graph without it on the same data (not the first data's), paired by evaluation seed
    assert lines[lines.index("## scene-play-v0"):].count(
        "A graph's setting against the same graph without it (each row's replanning in its file's name), on the same "
        "data, paired by evaluation seed (test tasks; verdict: better or worse beyond 2 standard errors, else tie): "
        "regenerated-data/graph-keep5-r1-objects-hand-afterstep25 minus regenerated-data/graph-keep5-r1-objects-"
        "afterstep25: +30.0 ± 5.8 (3 seeds, better).") == 1
    assert ("| scene-play-v0 | the dataset graph (no network: every 5th state, radius 1, one graph per part (cube, "
            "buttons, drawer, window), their steps in order, the window's and its button's graphs measuring the hand's "
            "opening too, replanned every 150 steps and 25 steps after a path's first step ends; on the recipe's data "
            "generated again here, sha256 56abd1befc8f130a) | 80.0 ± 0.0 (3 seeds) |") in mc.block(tmp_path)
    # searched again where a cube left its plan: named so, paired with the same graph without it
    for seed, (without, drift) in enumerate(((0.2, 0.5), (0.3, 0.5))):
        for folder, rate, replan in (("graph-keep5-r1-objects", without, 150),
                                     ("graph-keep5-r1-objects-objtol0.5", drift, 300)):
            path = tmp_path / mc.folder("cube-double") / mc.REGENERATED / folder / f"track-seed{seed}.json"
            write(path, rate, step=0, replan=replan)
            path.write_text(json.dumps({**json.loads(path.read_text()), "seed": seed}))
    found = mc.rows(tmp_path, "cube-double")
    assert mc.label("regenerated-data/graph-keep5-r1-objects-objtol0.5", found) == (
        "the dataset graph (no network: every 5th state, radius 1, one graph per cube, replanned every 300 steps and "
        "where a cube is more than 5 cm from its plan; on the recipe's data generated again here)")
    assert ("regenerated-data/graph-keep5-r1-objects-objtol0.5 minus regenerated-data/graph-keep5-r1-objects: +25.0 ± "
            "5.0 (2 seeds, better).") in mc.render(tmp_path)
    # a policy low level: one row per training seed of its policy, in folders -s<seed>, named by the policy
    for seed, rate in ((0, 0.8), (1, 0.9)):
        write(tmp_path / mc.folder("cube-double") / f"graph-keep5-r1-gciql-ahead25-s{seed}" /
              "track-replan50-seed0.json", rate, step=0, replan=50)
    assert "| graph-keep5-r1-gciql-ahead25 | test | 2 | 85.0 ± 5.0 | - | - |" in mc.render(tmp_path).splitlines()
    assert ("| cube-double-play-v0 | the dataset graph (every 5th state, radius 1, replanned every 50 steps), its "
            "paths executed by the policy of GCIQL (20 k steps) toward the path's state 25 steps on | 85.0 ± 5.0 (2 "
            "seeds) |") in mc.block(tmp_path)
    # a planner low level: named by its rows' settings
    low = tmp_path / mc.folder("cube-double") / "graph-keep5-r1-bridge-k4-nfe1-s0" / "track-replan12-high48-seed0.json"
    write(low, 0.3, step=20000, replan=12)
    row = json.loads(low.read_text())
    row["execution"]["replan_high_every"] = 48
    row["low"] = {"method": "bridge (coarse)", "subgoal_every": 3, "stride": 4, "horizon": 16, "nfe": 1,
                  "step": 20000, "config": {"preset": "cpu-small"}}
    low.write_text(json.dumps(row))
    assert mc.label("graph-keep5-r1-bridge-k4-nfe1", mc.rows(tmp_path, "cube-double")) == (
        "the dataset graph (every 5th state, radius 1, searched again every 48 steps), its path's states every 12 "
        "steps the subgoals of a bridge (coarse) low level (cpu-small, 20 k steps, 16 states 4 steps apart, NFE 1) "
        "replanned every 12 steps")
    # the goal table: the best planner (not GCBC, not GCIQL) per dataset against GCIQL here, published and the best
    # reported, by its mean; its margins in points
    goal = mc.render(tmp_path).splitlines()
    assert ("| cube-double | graph-keep5-r1-gciql-ahead25: 85.0 ± 5.0 (2 seeds) | not trained here | 40 (+45.0) | "
            "60 (+25.0) | `studies/manip-cube-double.toml` |") in goal
    assert ("| puzzle-3x3 | graph-keep10-r1.5: 70.0 (one run) | 90.0 (-20.0) | 95 (-25.0) | 95 (-25.0) | "
            "`studies/manip-puzzle-3x3.toml` |") in goal
    assert goal.index("## Against the goal") < goal.index("## cube-single-play-v0")
    # of equal means, the planner on more seeds
    for seed in range(3):
        path = tmp_path / mc.folder("puzzle-3x3") / "graph-keep10-r1.5-objects" / f"track-replan5-seed{seed}.json"
        write(path, 0.7, step=0, replan=5)
        path.write_text(json.dumps({**json.loads(path.read_text()), "seed": seed}))
    assert ("| puzzle-3x3 | graph-keep10-r1.5-objects: 70.0 ± 0.0 (3 seeds) | 90.0 (-20.0) |"
            in mc.render(tmp_path))


def test_the_manipulation_reports_low_levels_are_paired_with_ddpm_by_training_seed(tmp_path):
    """The graph over planner low levels: one row per process and NFE (test tasks only), the difference with DDPM at
    its largest NFE seed by seed (not the difference of the means), and a verdict only from 2 seeds on."""
    mc = report("manipulation")
    home = tmp_path / mc.folder("cube-single")

    def write(process, name, nfe, seed, rate, tasks=(1, 2, 3, 4, 5), step=20000):
        folder = home / f"graph-keep5-r1-{process}-k4-nfe{nfe}-s{seed}"
        path = folder / f"track-replan12-high48-step{step}-seed{1000 if min(tasks) > 5 else 0}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({
            "success_rate": rate, "seed": 1000 if min(tasks) > 5 else 0, "step": step,
            "decision_ms_batch1": {"p50": 2.0 * nfe},
            "execution": {"replan_every": 12, "replan_high_every": 48}, "high_alone": {"success_rate": 0.24},
            "low": {"method": name, "subgoal_every": 3, "stride": 4, "horizon": 16, "nfe": nfe, "step": 20000,
                    "config": {"preset": "cpu-small"}},
            "tasks": {str(t): {"success_rate": rate} for t in tasks}}))

    for seed, (ddpm, bridge) in enumerate(((0.10, 0.20), (0.30, 0.42), (0.50, 0.56))):
        write("ddpm", "DDPM", 16, seed, ddpm)
        write("ddpm", "DDPM", 1, seed, ddpm - 0.05)
        write("bridge", "bridge (coarse)", 1, seed, bridge)
    write("bridge", "bridge (coarse)", 1, 0, 0.9, tasks=(6, 7, 8, 9, 10))  # validation: not in this table
    write("meanflow", "mean flow (coarse)", 1, 0, 0.25)
    for seed, rate in enumerate((0.04, 0.26, 0.50)):  # the bridge from another prior: a row of its own
        write("bridge-line", "bridge (line)", 1, seed, rate)
    lines = mc.render(tmp_path).splitlines()
    assert ("| low level | NFE | seeds | success (%) | minus DDPM at NFE 16 (paired) | verdict | "
            "decision ms at batch 1 |") in lines
    # per-seed differences 10, 12, 6 points: mean 9.3, SE 1.8, beyond 2 SE: better
    assert "| bridge (coarse) | 1 | 3 | 39.3 ± 10.5 | +9.3 ± 1.8 (3) | better | 2.0 |" in lines
    assert "| DDPM | 1 | 3 | 25.0 ± 11.5 | -5.0 ± 0.0 (3) | worse | 2.0 |" in lines
    assert "| DDPM | 16 | 3 | 30.0 ± 11.5 | - | - | 32.0 |" in lines
    assert "| mean flow (coarse) | 1 | 1 | 25.0 | +15.0 (1) | - | 2.0 |" in lines
    assert any(line.startswith("Without a network: ") and line.endswith(": 24.0 % of the test episodes.")
               for line in lines)
    # the priors at NFE 1 against the plain line's, seed by seed: coarse minus line 16, 16, 6 points: mean 12.7, SE 3.3
    assert any(line.startswith("The bridge's priors at NFE 1, each paired by training seed with bridge (line)'s")
               and line.endswith(": bridge (coarse) +12.7 ± 3.3 (3 seeds, better).") for line in lines)
    # per-seed differences -6, -4, 0: mean -3.3, SE 1.8: a tie
    assert "| bridge (line) | 1 | 3 | 26.7 ± 13.3 | -3.3 ± 1.8 (3) | tie | 2.0 |" in lines
    assert lines.index("| bridge (coarse) | 1 | 3 | 39.3 ± 10.5 | +9.3 ± 1.8 (3) | better | 2.0 |") < lines.index(
        "| bridge (line) | 1 | 3 | 26.7 ± 13.3 | -3.3 ± 1.8 (3) | tie | 2.0 |")
    # an earlier snapshot of two seeds: a curve against training steps, the tables above still at the last snapshot
    write("bridge", "bridge (coarse)", 1, 0, 0.02, step=10000)
    write("bridge", "bridge (coarse)", 1, 1, 0.06, step=10000)
    lines = mc.render(tmp_path).splitlines()
    assert "| bridge (coarse) | 1 | 3 | 39.3 ± 10.5 | +9.3 ± 1.8 (3) | better | 2.0 |" in lines
    assert "| method | 10 k steps | 20 k steps | OGBench's average (last 3) |" in lines
    assert "| graph-keep5-r1-bridge-k4-nfe1 | 4.0 ± 2.0 (2) | 39.3 ± 10.5 (3) | - |" in lines
    assert not any(line.startswith("| graph-keep5-r1-ddpm-k4-nfe16 | ") and "(3)" in line for line in lines)
