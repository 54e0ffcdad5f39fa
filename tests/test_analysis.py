"""bridgeplan.analysis against small tables computed by hand, and against the committed results."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from bridgeplan.analysis.keys import OPEN_LOOP, MethodKey, describe, label, method, parse_execution
from bridgeplan.analysis.load import Point, Results, Row, read_csv, read_eval_json, row_from_csv
from bridgeplan.analysis.selection import BEST, FULL, Choice, best, resolve
from bridgeplan.analysis.stats import compare, finding_verdict, goal_verdict, mean_se, paired
from bridgeplan.analysis.tables import fmt_diff, fmt_mean_se, table
from bridgeplan.errors import BridgeplanError
from bridgeplan.replan import Execution
from bridgeplan.report import method_label
from tests.reports import report

controllers, findings, prior_curves = report("controllers"), report("findings"), report("prior-curves")

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"
CSVS = sorted(RESULTS.glob("*/results.csv"))


# --- mean ± standard error -------------------------------------------------------------------------------------

def test_mean_se_over_three_seeds():
    # [1, 2, 6]: mean 3; deviations -2, -1, 3; squares 4 + 1 + 9 = 14; sample variance 14 / 2 = 7;
    # SE = sqrt(7) / sqrt(3) = sqrt(7 / 3) = 1.5275...
    m = mean_se({0: 1.0, 1: 2.0, 2: 6.0})
    assert (m.mean, m.n) == (3.0, 3)
    assert m.se == pytest.approx(math.sqrt(7 / 3))
    assert fmt_mean_se(m) == "3.0 ± 1.5"


def test_one_seed_has_no_standard_error():
    m = mean_se([5.0])
    assert m.mean == 5.0 and m.n == 1 and math.isnan(m.se)
    assert fmt_mean_se(m) == "5.0 ± nan"  # findings.md's and controllers.md's way
    assert fmt_mean_se(m, one_seed="mean") == "5.0"  # prior-curves.md's way
    with pytest.raises(BridgeplanError, match="at least 2 seeds"):
        compare(m)
    with pytest.raises(BridgeplanError):
        mean_se([])


# --- paired differences and verdicts ---------------------------------------------------------------------------

A = {0: 10.0, 1: 12.0, 2: 14.0}
B = {0: 8.0, 1: 9.0, 2: 9.0}
# A - B = 2, 3, 5: mean 10/3 = 3.333; deviations -4/3, -1/3, 5/3; squares sum 42/9 = 4.667; variance 2.333;
# SE = sqrt(2.333 / 3) = 0.8819; mean - 2 SE = 1.57 > 0.


def test_paired_win():
    d = paired(A, B)
    assert d.mean == pytest.approx(10 / 3) and d.se == pytest.approx(math.sqrt(7 / 9)) and d.seeds == (0, 1, 2)
    assert fmt_diff(d) == "+3.3 ± 0.9"
    assert compare(d) == "better"
    assert finding_verdict(d, "above") == finding_verdict(d, "not below") == "holds"
    assert goal_verdict(d, "reaches") == goal_verdict(d, "clears") == "yes"


def test_paired_loss():
    d = paired(B, A)  # -3.3 ± 0.9: mean + 2 SE = -1.57 < 0
    assert fmt_diff(d) == "-3.3 ± 0.9"
    assert compare(d) == "worse"
    assert finding_verdict(d, "above") == finding_verdict(d, "not below") == "does not"
    assert goal_verdict(d, "reaches") == goal_verdict(d, "clears") == "no"


def test_paired_tie_either_side_of_zero():
    # differences 1, -1, 3: mean 1; deviations 0, -2, 2; variance 8 / 2 = 4; SE = 2 / sqrt(3) = 1.1547;
    # mean - 2 SE = -1.31 < 0 < mean + 2 SE = 3.31
    up = paired({0: 1.0, 1: -1.0, 2: 3.0}, {0: 0.0, 1: 0.0, 2: 0.0})
    assert up.se == pytest.approx(2 / math.sqrt(3))
    assert compare(up) == "tie"
    assert finding_verdict(up, "above") == "not decidable"
    assert finding_verdict(up, "not below") == "holds"
    assert goal_verdict(up, "reaches") == "yes" and goal_verdict(up, "clears") == "no"
    down = paired({0: 0.0, 1: 0.0, 2: 0.0}, {0: 1.0, 1: -1.0, 2: 3.0})  # -1.0 ± 1.2: below, within 2 SE
    assert compare(down) == "tie"
    assert finding_verdict(down, "above") == "not decidable" and finding_verdict(down, "not below") == "holds"
    assert goal_verdict(down, "reaches") == "within noise"


def test_paired_matches_by_seed_not_by_order():
    d = paired({2: 14.0, 0: 10.0, 1: 12.0}, {0: 8.0, 1: 9.0, 2: 9.0})
    assert d.mean == pytest.approx(10 / 3)


def test_paired_mismatched_seeds():
    with pytest.raises(BridgeplanError, match=r"only the first has \[2\], only the second \[3\]"):
        paired(A, {0: 8.0, 1: 9.0, 3: 9.0})
    d = paired(A, {0: 8.0, 1: 9.0, 3: 9.0}, seeds="common")  # 2 and 3 pair nothing: (10-8, 12-9) = 2, 3
    assert (d.mean, d.n, d.seeds) == (2.5, 2, (0, 1))
    with pytest.raises(BridgeplanError, match="share no seed"):
        paired({0: 1.0}, {1: 1.0}, seeds="common")
    with pytest.raises(BridgeplanError, match="unknown finding rule"):
        finding_verdict(paired(A, B), "below")


# --- choice on validation, report on test ----------------------------------------------------------------------

LINE = method("bridge", "line", steps=16)
PURSUIT = tuple(Execution(controller="pursuit", lookahead=r) for r in (0.5, 1))


def row(key: MethodKey, split: str, nfe: int, seed: int, score: float, step: int = 1000) -> Row:
    return Row(key=key, split=split, seed=seed, step=step, nfe=nfe, score=score, score_se=1.0, floor=40.0 + seed,
               success=0.5, calls=nfe, plan_ms=1.0)


def small_results() -> Results:
    # mean over seeds 0, 1:      validation   test
    #   NFE 1                    80 (79, 81)  90 (89, 91)   <- the best on the test episodes
    #   NFE 2                    85 (84, 86)  82 (81, 83)   <- the best on the validation episodes
    #   NFE 4                    70 (69, 71)  88 (87, 89)
    #   NFE 8                    -            99 (99, 99)   <- not validated: never chosen
    scores = {1: ((79, 81), (89, 91)), 2: ((84, 86), (81, 83)), 4: ((69, 71), (87, 89)), 8: (None, (99, 99))}
    rows = []
    for nfe, (validation, test) in scores.items():
        for split, values in (("validation", validation), ("test", test)):
            rows += [row(LINE, split, nfe, seed, v) for seed, v in enumerate(values or ())]
    return Results(rows)


def test_choice_on_validation_reports_its_test_rows():
    results = small_results()
    point = resolve(results, Choice(LINE, BEST), 1000)
    assert point == Point(LINE, 1000, 2)  # validation's pick, though NFE 1 (and 8) score higher on test
    assert results.values(point) == {0: 81, 1: 83}
    assert best(results, results.points(LINE, 1000), split="test") == Point(LINE, 1000, 8)
    assert best(results, [Point(LINE, 1000, 1), Point(LINE, 1000, 4)], split="test") == Point(LINE, 1000, 1)


def test_fixed_and_full_nfe_need_no_validation():
    results = small_results()
    assert resolve(results, Choice(LINE, 8), 1000) == Point(LINE, 1000, 8)
    assert resolve(results, Choice(LINE, FULL), 1000) == Point(LINE, 1000, 8)
    assert resolve(results, Choice(LINE, 16), 1000) is None
    assert resolve(results, Choice(LINE, BEST), 2000) is None  # nothing at that step


def test_a_choice_of_one_candidate_still_needs_validation():
    results = Results([row(LINE, "test", 1, 0, 90.0)])
    assert resolve(results, Choice(LINE, 1), 1000) == Point(LINE, 1000, 1)
    assert resolve(results, Choice(LINE, BEST), 1000) is None  # "best" on validation: there is none
    assert resolve(results, Choice(LINE, 1, among=(OPEN_LOOP,)), 1000) is None


def test_choice_among_executions():
    # pursuit 0.5: validation 60, test 95; pursuit 1: validation 70, test 75. Validation picks pursuit 1.
    rows = [row(LINE.replace(execution=PURSUIT[0]), "validation", 1, 0, 60),
            row(LINE.replace(execution=PURSUIT[0]), "test", 1, 0, 95),
            row(LINE.replace(execution=PURSUIT[1]), "validation", 1, 0, 70),
            row(LINE.replace(execution=PURSUIT[1]), "test", 1, 0, 75)]
    results = Results(rows)
    assert resolve(results, Choice(LINE, 1, among=PURSUIT), 1000) == Point(LINE.replace(execution=PURSUIT[1]), 1000, 1)
    no_validation = Results(r for r in rows if r.split == "test")
    assert resolve(no_validation, Choice(LINE, 1, among=PURSUIT), 1000) is None
    with pytest.raises(BridgeplanError):
        Choice(LINE, "most")


def test_first_row_of_an_evaluation_wins():
    results = Results([row(LINE, "test", 1, 0, 50.0), row(LINE, "test", 1, 0, 60.0), row(LINE, "test", 1, 1, 70.0)])
    assert results.values(Point(LINE, 1000, 1)) == {0: 50.0, 1: 70.0}
    assert len(results) == 2


# --- method keys from every committed schema -------------------------------------------------------------------

def test_every_committed_csv_is_read_in_todays_schema():
    """One schema: a row per evaluation, its split and the experiments that show it."""
    from bridgeplan.experiments.store import COLUMNS

    headers = {tuple(next(csv.reader(path.open()))) for path in CSVS}
    assert headers == {("id", "experiments", *COLUMNS)}
    for path in CSVS:
        raw = list(csv.DictReader(path.open()))
        rows = read_csv(path)
        assert len(rows) == len(raw)
        for r, x in zip(rows, raw):
            # the label is a function of the key, and equals what the run's config names the method
            assert label(r.key) == method_label(x) + (f" by {x['sampler']}" if x.get("sampler") else "")
            assert r.key.tag == (x.get("execution") or "")
            assert parse_execution(r.key.tag) == r.key.execution
            assert r.key.multi_task == bool(int(x.get("multi_task") or 0))
            assert r.key.steps == int(x["diffusion_steps"]) and r.key.process == x["process"]
            assert r.split == x["split"] == ("validation" if int(x["eval_seed"]) >= 1000 else "test")
            if x["network_calls_per_plan"]:
                assert r.network_calls == float(x["network_calls_per_plan"]) >= r.nfe
                if not r.key.execution.replan_every:  # the plans' residuals are measured open loop only
                    assert r.plan_dynamics == float(x["plan_dynamics_rms"]) > 0


OLD_SCHEMAS = {  # the committed CSVs' headers before the store was keyed by evaluation (one row per experiment)
    1: "id,experiment,run_name,maze,process,prior,diffusion_steps,seed,step,train_seconds,nfe,episodes,eval_seed,"
       "score_minari,score_minari_se,score_d4rl,score_d4rl_se,success_rate,plan_ms,prior_ms,floor_minari,config,"
       "code_version,created",
    2: "id,experiment,run_name,maze,process,prior,diffusion_steps,seed,step,train_seconds,nfe,episodes,eval_seed,"
       "score_minari,score_minari_se,score_d4rl,score_d4rl_se,success_rate,plan_ms,prior_ms,floor_minari,execution,"
       "multi_task,calls_per_episode,decision_ms_p50,decision_ms_p95,config,code_version,created",
    3: "id,experiment,run_name,maze,process,prior,diffusion_steps,seed,step,train_seconds,nfe,episodes,eval_seed,"
       "score_minari,score_minari_se,score_d4rl,score_d4rl_se,success_rate,plan_ms,prior_ms,floor_minari,execution,"
       "multi_task,sampler,calls_per_episode,decision_ms_p50,decision_ms_p95,config,code_version,created",
    4: "id,experiment,run_name,maze,process,prior,diffusion_steps,seed,step,train_seconds,nfe,episodes,eval_seed,"
       "score_minari,score_minari_se,score_d4rl,score_d4rl_se,success_rate,plan_ms,prior_ms,floor_minari,execution,"
       "multi_task,sampler,calls_per_episode,decision_ms_p50,decision_ms_p95,network_calls_per_plan,"
       "plan_kinematics_rms,plan_dynamics_rms,config,code_version,created",
}


def as_old_schema(path: Path, out: Path, version: int) -> int:
    """``path`` (today's schema) written in an older one: a row per experiment and evaluation (the evaluations an
    older schema could not hold left out); returns the evaluations written."""
    fields = OLD_SCHEMAS[version].split(",")
    rows, evaluations = [], 0
    for x in csv.DictReader(path.open()):
        if (version == 1 and (x["execution"] or x["multi_task"] != "0")) or (version <= 2 and x["sampler"]):
            continue
        evaluations += 1
        rows += [{k: (name if k == "experiment" else x[k]) for k in fields} for name in x["experiments"].split()]
    with out.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    return evaluations


@pytest.mark.parametrize("version", sorted(OLD_SCHEMAS))
def test_an_older_csv_schema_reads_and_imports_as_todays(tmp_path, version):
    """The older schemas (one row per experiment and evaluation, the split in the experiment's name) give the same
    analysis rows, and import into a store as the same evaluations with the same memberships."""
    from bridgeplan.experiments.store import ResultsStore, read_csv_rows

    path = RESULTS / "medium-v2-hold" / "results.csv"  # closed-loop and validation rows, shared evaluations
    old = tmp_path / "old.csv"
    evaluations = as_old_schema(path, old, version)
    assert evaluations >= 20
    today = {(r.key, r.split, r.step, r.nfe, r.seed): r for r in read_csv(path)}
    rows = read_csv(old)
    assert len(rows) > evaluations  # some evaluations are shown by several experiments
    for r in rows:
        mine = today[r.key, r.split, r.step, r.nfe, r.seed]
        assert (r.score, r.floor, r.success, r.run_name) == (mine.score, mine.floor, mine.success, mine.run_name)
        assert r.experiment in mine.experiment.split()
    store = ResultsStore(tmp_path / "results.sqlite")
    assert store.import_rows(read_csv_rows(old)) == (evaluations, evaluations)
    assert store.import_rows(read_csv_rows(path))[1] == sum(1 for _ in csv.DictReader(path.open())) - evaluations
    expected = {(x["run_name"], x["step"], x["nfe"], x["sampler"], x["execution"], x["eval_seed"]):
                (x["experiments"], x["split"], float(x["score_minari"])) for x in csv.DictReader(path.open())}
    stored = {(x["run_name"], str(x["step"]), str(x["nfe"]), x["sampler"], x["execution"], str(x["eval_seed"])):
              (x["experiments"], x["split"], x["score_minari"]) for x in store.rows()}
    assert stored == expected


def first(path: str, **match) -> dict:
    return next(r for r in csv.DictReader((RESULTS / path).open()) if all(r[k] == v for k, v in match.items()))


def test_keys_from_configs_that_spell_defaults_or_not():
    # medium-v2-curves' consistent runs predate predict/weighting in the config; the consistent-priors store's
    # configs spell them out at their defaults: one key
    old = row_from_csv(first("medium-v2-curves/results.csv", split="test", prior="line",
                             run_name="medium-bridge-line-N16-consistent-H32k8-cpu-small-s0"))
    new = row_from_csv(first("medium-v2-consistent-priors/results.csv", prior="line"))
    assert old.key == new.key == method("bridge", "line", steps=16, consistent=True)
    assert label(new.key) == "bridge (line; consistent=True)"
    assert method("bridge", "line", steps=16, predict="eps") == method("bridge", "line", steps=16)


def test_keys_of_samplers_holds_executions_and_version_1_rows():
    ddim = row_from_csv(first("medium-v2-sampler-sweep/results.csv", process="ddpm", sampler="ddim"))
    assert ddim.key == method("ddpm", steps=16, sampler="ddim") and label(ddim.key) == "DDPM by ddim"
    hold = row_from_csv(first("umaze-v2-hold/results.csv", process="ddpm", execution="replan32-arrival-keep"))
    assert hold.key == method("ddpm", steps=16, hold_share=0.5, execution=Execution(replan_every=32, arrival="keep"),
                              multi_task=hold.key.multi_task)
    assert label(hold.key) == "DDPM, hold 0.5"
    assert describe(hold.key).startswith("DDPM, hold 0.5, N=16, replan32-arrival-keep, ")
    v1 = row_from_csv(first("../history/umaze-cpu-small/results.csv", process="bridge", prior="line", nfe="4"))
    assert v1.key.execution == OPEN_LOOP and not v1.key.multi_task and v1.decision_ms is None
    assert v1.calls == v1.nfe == 4  # rows made by version 1 have no calls: one call per NFE
    assert label(v1.key) == "bridge (line; beta_max=0.3)"
    with pytest.raises(BridgeplanError):
        method("bridge", "line", steps=16, beta=0.3)


def test_a_damaged_row_names_its_file_and_id():
    r = dict(first("umaze-v2-hold/results.csv", process="ddpm"), process="bridge")
    with pytest.raises(BridgeplanError, match=r"x.csv row \d+: column process is 'bridge', its config says 'ddpm'"):
        row_from_csv(r, source="x.csv")
    with pytest.raises(BridgeplanError, match="x.csv row"):
        row_from_csv(dict(r, process="ddpm", execution="pursuit"), source="x.csv")


@pytest.mark.parametrize("tag, execution", [
    ("", Execution()),
    ("pursuit1.5", Execution(controller="pursuit", lookahead=1.5)),
    ("replan32-warm-arrival-keep", Execution(replan_every=32, warm=True, arrival="keep")),
    ("replan32-warm-pursuit1", Execution(replan_every=32, warm=True, controller="pursuit", lookahead=1)),
    ("tol0.5-cand8-agreement-arrival-end", Execution(tolerance=0.5, candidates=8, select="agreement", arrival="end")),
    ("replan150-afterstep25", Execution(replan_every=150, after_step=25)),
    ("replan150-objtol0.5", Execution(replan_every=150, object_tolerance=0.5)),
])
def test_execution_tags_round_trip(tag, execution):
    assert parse_execution(tag) == execution and execution.tag() == tag
    assert Execution.from_dict(execution.to_dict("line")) == execution


@pytest.mark.parametrize("tag", ["pursuit", "replanX", "warm-replan32", "cand8", "arrival", "sprint1", "replan32-"])
def test_unknown_execution_tags(tag):
    with pytest.raises(BridgeplanError, match="unknown execution tag"):
        parse_execution(tag)


def test_eval_json_rows():
    r = read_eval_json(RESULTS / "medium-v2-curves" / "learned-floor" / "s1.json")
    assert r.key == method("bridge", "learned", steps=16) and label(r.key) == "bridge (learned)"
    assert (r.seed, r.nfe, r.split) == (1, 1, "test") and r.floor > 0 and r.floor_learned > 0


def test_an_eval_json_row_is_of_its_runs_training_seed_on_its_own_evaluation_seed(tmp_path):
    """A validation evaluation (task seed 1000 + s) or one on pinned episodes (task seed 0 for every run) is a row of
    the run's training seed, its evaluation seed beside it."""
    import json

    d = json.loads((RESULTS / "medium-v2-curves" / "learned-floor" / "s1.json").read_text())
    (tmp_path / "v.json").write_text(json.dumps({**d, "seed": 1001}))
    r = read_eval_json(tmp_path / "v.json", "x-validation")
    assert (r.seed, r.eval_seed, r.split) == (1, 1001, "validation")


# --- Markdown ---------------------------------------------------------------------------------------------------

def test_markdown_table():
    assert table(["maze", "score"], [["umaze", fmt_mean_se([1.0, 2.0, 6.0])], ["large", 7]]) == [
        "| maze | score |", "|---|---|", "| umaze | 3.0 ± 1.5 |", "| large | 7 |"]
    with pytest.raises(BridgeplanError, match="1 cells for 2 columns"):
        table(["a", "b"], [["x"]])


def test_findings_md_regenerates_from_the_committed_csvs():
    assert findings.render(RESULTS) + "\n" == (RESULTS / "findings.md").read_text()


def test_prior_curves_md_regenerates_from_the_committed_results():
    assert prior_curves.render(RESULTS) + "\n" == (RESULTS / "prior-curves.md").read_text()


def test_controllers_md_regenerates_from_the_committed_csvs():
    assert controllers.render(RESULTS) + "\n" == (RESULTS / "controllers.md").read_text()
