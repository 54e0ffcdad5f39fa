"""`bridgeplan bench` through the real CLI with tiny settings: what it writes, and its refusals."""

from __future__ import annotations

import json
import os
import shutil

import pytest

from bridgeplan.bench import suites
from bridgeplan.cli import main
from bridgeplan.nets.unet import FrozenUNet

TINY_BENCH = ["--presets", "cpu-small", "--batch-sizes", "1", "--nfes", "1,2", "--repeats", "1",
              "--overhead-repeats", "2", "--no-compile", "--throughput-seconds", "0", "--side-by-side-seconds", "0",
              "--device", "cpu"]


@pytest.mark.slow
def test_bench_writes_every_table(tiny_runs, tmp_path, capsys):
    runs = f"{tiny_runs['ddpm']},{tiny_runs['bridge']}"
    assert main(["bench", "--out", str(tmp_path), *TINY_BENCH, "--budget-runs", runs, "--budgets", "1,2,4",
                 "--budget-steps", "2,3", "--budget-episodes", "4"]) == 0
    result = json.loads((tmp_path / "bench.json").read_text())
    markdown = (tmp_path / "bench.md").read_text()
    assert capsys.readouterr().out.strip() == markdown.strip()
    assert result["bench"]["presets"] == ["cpu-small"] and result["machine"]["device"] == "cpu"

    methods = {r["method"] for r in result["latency"]}
    one_call = {"mean flow (line)", "shortcut (line)"}
    assert methods == {"DDPM [ancestral]", "DDPM [ddim]", "bridge (gaussian)", "bridge (line)", "bridge (learned)",
                       *one_call}
    assert {(r["batch"], r["nfe"]) for r in result["latency"]} == {(1, 1), (1, 2)}
    # each timed (a plan includes its prior's sampling, but two medians of a loaded machine may come either way)
    assert all(r["plan_ms"] > 0 and r["prior_ms"] > 0 for r in result["latency"])
    (overhead,) = result["plan_overhead"]
    assert set(overhead["plan_nfe1_over_forward"]) == methods - one_call  # their network has two time inputs
    assert all(0 < v < 100 for v in overhead["plan_nfe1_over_forward"].values())
    (train,) = result["train_overhead"]
    assert (train["batch"], train["grad_accum"]) == (32, 1) and train["train_step_over_bare"] > 0
    assert "| cpu-small | 32 x 1 |" in markdown
    assert result["compile"] == [] and result["throughput"] == [] and result["side_by_side"] == []

    budget = result["score_per_budget"]
    evals = budget["evaluations"]
    # the tiny runs at both snapshots, on validation and test tasks, each under both its samplers: DDPM with N=6
    # (ancestral, ddim), the bridge (N=6, NFE < N; posterior, mean) at every K
    splits = ("test", "validation")
    assert sorted((e["method"], e["step"], e["sampler"], e["nfe"], e["split"]) for e in evals
                  if e["method"] == "DDPM") == [
        ("DDPM", step, s, k, split) for step in (2, 3) for s in ("ancestral", "ddim") for k in (1, 2, 4)
        for split in splits]
    assert sorted((e["step"], e["sampler"], e["nfe"], e["split"]) for e in evals
                  if e["method"] == "bridge (learned)") == [
        (step, s, k, split) for step in (2, 3) for s in ("mean", "posterior") for k in (1, 2, 4) for split in splits]
    assert len(budget["best"]) == 2 * 2 * 3  # methods x training steps x budgets

    def score(best, split):
        (e,) = [e for e in evals if (e["method"], e["step"], e["sampler"], e["nfe"], e["split"]) ==
                (best["method"], best["step"], best["sampler"], best["nfe"], split)]
        return e["score_minari"]

    for best in budget["best"]:
        within = [e["score_minari"]["mean"] for e in evals if e["method"] == best["method"]
                  and e["step"] == best["step"] and e["nfe"] <= best["budget"] and e["split"] == "validation"]
        # chosen on validation tasks, reported on the test tasks
        assert best["validation_score_minari"]["mean"] == max(within) and best["nfe"] <= best["budget"]
        assert best["validation_score_minari"] == score(best, "validation")
        assert best["score_minari"] == score(best, "test")
    assert "## Score per planning budget" in markdown
    assert "| DDPM | 2 |" in markdown and "| DDPM | 3 |" in markdown
    assert "Unequal training budgets" not in markdown


@pytest.mark.parametrize("bad, message", [
    (["--device", "cuda:7"], "cuda"),
    (["--batch-sizes", "0"], "--batch-sizes takes positive integers"),
    (["--repeats", "0"], "repeats must be positive"),
    (["--presets", "huge"], "unknown preset"),
    (["--budget-runs", "no/such/run"], "no run at no/such/run"),
    (["--budget-steps", "0"], "--budget-steps takes positive integers"),
    (["--side-by-side-seconds", "-1"], "side-by-side-seconds must be >= 0"),
    (["--methods", "DDPM [fast]"], "unknown method 'DDPM [fast]'"),
    (["--overhead-repeats", "-1"], "overhead-repeats must be >= 0"),
    (["--mazes", "medium,maze9"], "unknown maze 'maze9'"),
])
def test_bench_bad_input(tmp_path, capsys, bad, message):
    assert main(["bench", "--out", str(tmp_path), "--no-compile", *bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "bench.json").exists()


def test_bench_times_the_methods_asked_for_at_any_nfe_and_skips_the_overheads(tmp_path, capsys):
    """``--methods`` keeps the latency table to those methods; an NFE above 16 gets networks with enough steps
    (the bridge takes N - 1 at most); ``--overhead-repeats 0`` skips the overhead tables."""
    args = [*TINY_BENCH, "--methods", "DDPM [ancestral],bridge (line)", "--nfes", "1,20", "--overhead-repeats", "0",
            "--busy-steps", "0"]  # the busy-core figure is another test's
    assert main(["bench", "--out", str(tmp_path), *args]) == 0
    capsys.readouterr()
    result = json.loads((tmp_path / "bench.json").read_text())
    assert sorted((r["method"], r["nfe"]) for r in result["latency"]) == [
        ("DDPM [ancestral]", 1), ("DDPM [ancestral]", 20), ("bridge (line)", 1), ("bridge (line)", 20)]
    assert result["plan_overhead"] == [] and result["train_overhead"] == []
    assert "Untrained networks with N = 21 for the timings" in (tmp_path / "bench.md").read_text()


def test_bench_times_the_plans_of_each_maze_asked_for(tmp_path, capsys, monkeypatch):
    """``--mazes``: each maze's plans at its preset's shape (cpu-small: umaze 128 states one step apart, medium 32
    states 8 apart), the shape in each row and in the table."""
    shapes = []
    plan = suites.Planner.plan
    monkeypatch.setattr(suites.Planner, "plan", lambda self, *a: shapes.append((self.horizon, self.stride)) or
                        plan(self, *a))
    args = [*TINY_BENCH, "--methods", "bridge (line)", "--nfes", "1", "--overhead-repeats", "0", "--busy-steps", "0",
            "--mazes", "umaze,medium"]
    assert main(["bench", "--out", str(tmp_path), *args]) == 0
    capsys.readouterr()
    rows = json.loads((tmp_path / "bench.json").read_text())["latency"]
    assert [(r["maze"], r["horizon"], r["stride"]) for r in rows] == [("umaze", 128, 1), ("medium", 32, 8)]
    assert set(shapes) == {(128, 1), (32, 8)}
    text = (tmp_path / "bench.md").read_text()
    assert "| cpu-small | medium, 32 x 8 | bridge (line) | 1 | 1 |" in text and "| umaze, 128 x 1 |" in text


def test_bench_times_the_one_call_processes_at_the_nfes_they_take(tmp_path, capsys, monkeypatch):
    """The mean flow and the shortcut model (their network takes a second time input) are timed like the others;
    the shortcut model only at powers of two, on a network of N a power of two (N = 32 for NFE 20); ``--frozen``
    times each through its network traced and frozen as well."""
    args = [*TINY_BENCH, "--methods", "mean flow (line),shortcut (line)", "--nfes", "1,3,20", "--overhead-repeats",
            "0", "--busy-steps", "0", "--frozen"]
    frozen = []
    monkeypatch.setattr(suites, "FrozenUNet", lambda net, horizon: frozen.append(net) or FrozenUNet(net, horizon))
    assert main(["bench", "--out", str(tmp_path), *args]) == 0
    assert len(frozen) == 2 and all(net.interval_mlp is not None for net in frozen)
    capsys.readouterr()
    result = json.loads((tmp_path / "bench.json").read_text())
    rows = result["latency"]
    m = result["machine"]
    assert m["load_1min_start"] >= 0 and m["load_1min_end"] >= 0
    assert f"load average was {m['load_1min_start']:.1f} at the start" in (tmp_path / "bench.md").read_text()
    assert "(the latency table's figures alternating, a call of each per round)" in (tmp_path / "bench.md").read_text()
    assert sorted((r["method"], r["nfe"]) for r in rows) == [
        ("mean flow (line)", 1), ("mean flow (line)", 3), ("mean flow (line)", 20), ("mean flow (line), frozen", 1),
        ("mean flow (line), frozen", 3), ("mean flow (line), frozen", 20), ("shortcut (line)", 1),
        ("shortcut (line), frozen", 1)]
    assert all(r["plan_ms"] > 0 and r["prior_ms"] > 0 for r in rows)


def test_bench_refuses_a_missing_snapshot_before_timing_anything(tiny_runs, tmp_path, capsys):
    assert main(["bench", "--out", str(tmp_path), *TINY_BENCH, "--budget-runs", str(tiny_runs["ddpm"]),
                 "--budget-steps", "3,5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: no snapshot at step 5 in {tiny_runs['ddpm']} (have: [2, 3])"]
    assert not (tmp_path / "bench.json").exists()


@pytest.mark.slow
def test_bench_keeps_two_runs_of_one_method_apart(tiny_runs, tmp_path, capsys):
    """Two DDPM runs (say two seeds) are two rows, never one best pooled over both."""
    twin = tmp_path / "ddpm-twin"
    shutil.copytree(tiny_runs["ddpm"], twin)
    assert main(["bench", "--out", str(tmp_path / "out"), *TINY_BENCH, "--budget-runs",
                 f"{tiny_runs['ddpm']},{twin}", "--budgets", "1", "--budget-episodes", "2"]) == 0
    capsys.readouterr()
    best = json.loads((tmp_path / "out" / "bench.json").read_text())["score_per_budget"]["best"]
    assert sorted(b["run"] for b in best) == sorted([tiny_runs["ddpm"].name, twin.name])
    markdown = (tmp_path / "out" / "bench.md").read_text()
    assert "| DDPM (ddpm) | 3 |" in markdown and "| DDPM (ddpm-twin) | 3 |" in markdown


@pytest.mark.slow
def test_training_throughput_rows_against_the_machine_limit(monkeypatch):
    import torch

    from bridgeplan.nets.unet import Mish

    monkeypatch.setattr(suites, "THROUGHPUT_MAZES", ("medium",))  # one shape is enough here
    monkeypatch.setattr(suites, "machine_limit", lambda threads, dtype, dev: {"matmul": 100.0, "conv": 50.0})
    references = []
    real_reference = suites.with_torch_reference

    def spy(job):
        real_reference(job)
        references.append(job.model)

    monkeypatch.setattr(suites, "with_torch_reference", spy)
    rows = suites.training_throughput("cpu-small", (8,), 0.01, torch.device("cpu"))
    precisions = ["fp32"] + (["bf16"] if suites_bf16() else [])
    threads = sorted({1, os.cpu_count() or 1})
    busy = (0, 1) if (os.cpu_count() or 1) > 1 else (0,)
    # every setting (and the reference at batch 32, fp32) at every busy x threads combination
    assert sorted((r["batch"], r["precision"], r["implementation"], r["busy_cores"], r["threads"]) for r in rows) == \
        sorted([(8, p, "bridgeplan", b, t) for p in precisions for b in busy for t in threads] +
               [(32, "fp32", "reference", b, t) for b in busy for t in threads])
    for r in rows:
        assert (r["maze"], r["horizon"], r["stride"]) == ("medium", 32, 8)
        assert r["windows_per_s"] == pytest.approx(r["batch"] / (r["step_ms"] / 1000))
        assert r["gflops"] == pytest.approx(r["gflop_per_step"] / (r["step_ms"] / 1000))
        assert r["fraction_of_matmul"] == pytest.approx(r["gflops"] / 100) and \
            r["fraction_of_conv"] == pytest.approx(r["gflops"] / 50)
    # FLOPs per step scale with the batch: 0.44 GFLOP at 32 (the count of cpu-small at medium's shape)
    (ref_flops,) = {r["gflop_per_step"] for r in rows if r["batch"] == 32}
    (flops,) = {r["gflop_per_step"] for r in rows if r["batch"] == 8}
    assert ref_flops == pytest.approx(0.44, rel=0.02) and flops == pytest.approx(ref_flops / 4)
    # the reference rows ran torch's Mish, none of bridgeplan's
    assert references and all(not any(isinstance(m, Mish) for m in net.modules()) and
                              any(isinstance(m, torch.nn.Mish) for m in net.modules()) for net in references)


@pytest.mark.slow
def test_training_throughput_times_the_compiled_step_when_asked(monkeypatch):
    import torch

    from bridgeplan.bench.markdown import format_throughput
    from bridgeplan.nets.unet import TemporalUNet

    monkeypatch.setattr(suites, "THROUGHPUT_MAZES", ("medium",))
    monkeypatch.setattr(suites, "machine_limit", lambda threads, dtype, dev: {"matmul": 100.0, "conv": 50.0})
    compiled = []
    monkeypatch.setattr(torch, "compile", lambda model: compiled.append(model) or model)  # no compiler in the test
    rows = suites.training_throughput("cpu-small", (8,), 0.01, torch.device("cpu"), compiled=True)
    timed = [r for r in rows if r["implementation"] == "compiled"]
    settings = len(sorted({1, os.cpu_count() or 1})) * (2 if (os.cpu_count() or 1) > 1 else 1)
    assert len(timed) == settings and {(r["batch"], r["precision"]) for r in timed} == {(8, "fp32")}
    assert len(compiled) == 1 and isinstance(compiled[0], TemporalUNet)  # one network compiled, for those rows
    assert all(r["compile_s"] > 0 for r in timed)
    assert all(r["compile_s"] is None for r in rows if r["implementation"] != "compiled")
    assert f"| compiled ({timed[0]['compile_s']:.0f} s) |" in "\n".join(format_throughput(rows, 1024))


@pytest.mark.slow
@pytest.mark.skipif((os.cpu_count() or 1) < 2 or os.name != "posix", reason="a second core; POSIX signals")
def test_two_jobs_side_by_side(monkeypatch):
    import torch

    from bridgeplan.bench.markdown import format_side_by_side

    monkeypatch.setattr(suites, "THROUGHPUT_MAZES", ("umaze",))  # one shape, one batch (cpu-small's 32)
    turns = []
    real = suites.running_only
    monkeypatch.setattr(suites, "running_only", lambda procs, running: turns.append(len(running)) or
                        real(procs, running))
    rows = suites.side_by_side_training("cpu-small", 0.06, torch.device("cpu"), rounds=2)
    assert [(r["maze"], r["batch"], r["other_core"], r["rounds"]) for r in rows] == [
        ("umaze", 32, "quiet", 2), ("umaze", 32, "spinning", 2), ("umaze", 32, "training", 2)]
    assert turns == [0, 1, 1] * 2  # the settings alternate: nothing else running, then one other process
    for r in rows:
        assert r["windows_per_s"] == pytest.approx(32 * r["steps_per_s"])
        assert r["beside_over_alone"] == pytest.approx(r["steps_per_s"] / rows[0]["steps_per_s"])
    markdown = "\n".join(format_side_by_side(rows))
    assert "## Two jobs side by side" in markdown and "| cpu-small | umaze 128 x 1 | 32 | fp32 | training |" in markdown


def test_a_busy_process_is_waited_for_until_ready_and_one_that_dies_first_is_an_error():
    import time

    from bridgeplan.bench.harness import busy_cores
    from bridgeplan.errors import BridgeplanError

    t0 = time.perf_counter()
    with busy_cores(1, "import time; time.sleep(1.5); print('ready', flush=True); time.sleep(60)"):
        assert time.perf_counter() - t0 >= 1.5
    with pytest.raises(BridgeplanError, match="ended first"):
        with busy_cores(1, "raise SystemExit(3)"):
            pass


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="reads process states from Linux's /proc")
def test_running_only_pauses_the_other_processes():
    from bridgeplan.bench.harness import busy_cores, running_only

    def state(p) -> str:  # R running, S sleeping, T stopped
        with open(f"/proc/{p.pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]

    with busy_cores(2) as procs:
        running_only(procs, procs[:1])
        assert state(procs[0]) in "RS" and state(procs[1]) == "T"
        running_only(procs, [])
        assert [state(p) for p in procs] == ["T", "T"]
        running_only(procs, procs)
        assert all(state(p) in "RS" for p in procs)


def suites_bf16() -> bool:
    import torch

    from bridgeplan.train import bf16_supported

    return bf16_supported(torch.device("cpu"))


def test_the_machine_names_its_cpu_and_the_extensions_that_decide_its_speed():
    from bridgeplan.device import cpu_model

    amx = "processor\t: 0\nmodel name\t: Intel Xeon\nflags\t\t: fpu avx2 avx512f amx_bf16 sse\n"
    assert cpu_model(amx) == "Intel Xeon (avx2, avx512f, amx_bf16)"
    assert cpu_model("model name : AMD EPYC\nflags : fpu avx2\n") == "AMD EPYC (avx2)"
    assert cpu_model("model name : Some CPU\nflags : fpu\n") == "Some CPU"
    assert cpu_model("Hardware : arm\n") == ""  # no model name: none said
