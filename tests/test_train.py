"""Training through the real CLI with tiny settings: smoke runs, exact resume, bad input."""

from __future__ import annotations

import json

import pytest
import torch

from bridgeplan import files
from bridgeplan.cli import main
from bridgeplan.device import cpu_model

TINY = ["--preset", "cpu-small", "--horizon", "32", "--dim", "8", "--dim-mults", "1,2",
        "--diffusion-steps", "6", "--batch-size", "4", "--ema-start", "2", "--ema-every", "1",
        "--log-every", "1", "--no-progress", "--device", "cpu"]


def train_args(dataset, run_dir, steps, *extra):
    return ["train", "--maze", "umaze", "--dataset", dataset, "--run-dir", str(run_dir),
            "--steps", str(steps), *TINY, *extra]


def weights(run_dir):
    state = torch.load(run_dir / "checkpoint.pt", weights_only=False)
    return state["model"], state["ema"], state["step"]


HOLD_AND_ABLATION = ["--hold-share", "0.5", "--process-param", "predict=x0", "--process-param", "weighting=uniform"]


@pytest.mark.parametrize("process,extra", [("ddpm", []), ("bridge", []), ("bridge", HOLD_AND_ABLATION)])
def test_resume_is_exact(tiny_dataset, tmp_path, process, extra):
    straight, interrupted = tmp_path / "straight", tmp_path / "interrupted"
    flags = ["--process", process] + (["--prior", "line"] if process == "bridge" else []) + extra
    assert main(train_args(tiny_dataset, straight, 6, *flags)) == 0
    assert main(train_args(tiny_dataset, interrupted, 3, *flags)) == 0
    assert weights(interrupted)[2] == 3
    assert main(train_args(tiny_dataset, interrupted, 6, *flags, "--resume")) == 0
    (m1, e1, s1), (m2, e2, s2) = weights(straight), weights(interrupted)
    assert s1 == s2 == 6
    for key in m1:
        assert torch.equal(m1[key], m2[key]), key
        assert torch.equal(e1[key], e2[key]), key
    # the EMA really moved away from the raw weights after ema_start
    assert any(not torch.equal(m1[k], e1[k]) for k in m1 if m1[k].is_floating_point())


def test_run_directory_holds_config_and_snapshots(tiny_dataset, tmp_path):
    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 4, "--checkpoint-every", "2")) == 0
    saved = json.loads((run / "config.json").read_text())
    assert saved["kind"] == "planner" and saved["cpu"] == cpu_model()
    assert saved["config"]["maze"] == "umaze" and saved["config"]["horizon"] == 32
    assert saved["config"]["model"]["dim_mults"] == [1, 2]
    assert sorted(p.name for p in (run / "snapshots").iterdir()) == ["step_00000002.pt", "step_00000004.pt"]


def test_hold_share_and_loss_variants_are_saved_and_checked(tiny_dataset, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 2, "--process", "bridge", *HOLD_AND_ABLATION)) == 0
    saved = json.loads((run / "config.json").read_text())["config"]
    assert saved["hold_share"] == 0.5
    assert saved["process"]["predict"] == "x0" and saved["process"]["weighting"] == "uniform"
    for bad, message in ((["--hold-share", "1.5"], "hold_share must be in [0, 1]"),
                         (["--process-param", "weighting=snr"], "unknown weighting 'snr'")):
        capsys.readouterr()
        assert main(train_args(tiny_dataset, tmp_path / "bad", 2, "--process", "bridge", *bad)) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "bad").exists()


def test_a_training_logged_to_a_file_draws_its_bar_once_a_minute_not_every_step(tiny_dataset, tmp_path, capsys):
    # stderr captured is not a terminal, as a log under nohup: the bar at its start and end only, though every step
    # logs its loss (--log-every 1) and a step takes milliseconds
    args = [a for a in train_args(tiny_dataset, tmp_path / "run", 40) if a != "--no-progress"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "40/40" in err and err.count("\r") <= 3, err


def test_existing_run_without_resume_is_refused(tiny_dataset, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 2)) == 0
    before = (run / "checkpoint.pt").read_bytes()
    assert main(train_args(tiny_dataset, run, 2)) == 2
    assert "already exists" in capsys.readouterr().err
    assert (run / "checkpoint.pt").read_bytes() == before


def test_run_killed_while_writing_its_first_config_starts_again(tiny_dataset, tmp_path):
    # what a kill before config.json's rename leaves: the lock and mkstemp's temporary file
    run = tmp_path / "run"
    run.mkdir()
    (run / ".lock").touch()
    (run / ".config.json.k1ll3d.tmp").write_text('{"kind": ')
    assert main(train_args(tiny_dataset, run, 2)) == 0
    assert weights(run)[2] == 2 and not list(run.glob(".*.tmp"))


def test_run_killed_while_probing_its_directory_starts_again(tiny_dataset, tmp_path, monkeypatch):
    # what a kill between check_writable's probe and its removal leaves (a sweep killed as a run starts)
    run = tmp_path / "run"
    run.mkdir()
    with monkeypatch.context() as m:
        m.setattr(files.os, "unlink", lambda path: None)
        files.check_writable(run, folder=True)
    assert len(list(run.iterdir())) == 1
    assert main(train_args(tiny_dataset, run, 2)) == 0
    assert weights(run)[2] == 2 and not list(run.glob(".*.tmp"))


def test_resume_with_other_config_is_refused(tiny_dataset, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 2)) == 0
    assert main(train_args(tiny_dataset, run, 4, "--lr", "0.1", "--resume")) == 2
    err = capsys.readouterr().err
    assert "different config" in err and "lr" in err


@pytest.mark.parametrize("bad, message", [
    (["--process", "magic"], "unknown process"),
    (["--preset", "huge"], "unknown preset"),
    (["--horizon", "31"], "divisible"),
    (["--steps", "0"], "steps must be positive"),
    (["--process", "bridge", "--prior", "magic"], "unknown prior"),
    (["--process", "bridge", "--prior", "learned"], "--prior-run"),
    (["--lr", "-1"], "lr must be a positive, finite number"),
    (["--lr", "nan"], "lr must be a positive, finite number"),
    (["--batch-size", "0"], "batch_size must be positive"),
    (["--grad-accum", "0"], "grad_accum must be >= 1"),
    (["--ema-decay", "1.5"], "ema_decay must be in [0, 1]"),
    (["--checkpoint-every", "0"], "checkpoint_every must be positive"),
    (["--precision", "fp16"], "unknown precision 'fp16'"),
])
def test_bad_input(tiny_dataset, tmp_path, capsys, bad, message):
    run = tmp_path / "run"
    args = train_args(tiny_dataset, run, 2)
    # later flags win in argparse
    assert main(args + bad) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and message in err[0], err
    assert not (run / "checkpoint.pt").exists()


def test_nan_loss_stops_and_keeps_last_checkpoint(tiny_dataset, tmp_path, capsys):
    run = tmp_path / "run"
    # a huge learning rate makes the loss blow up to inf/NaN after the first update
    assert main(train_args(tiny_dataset, run, 50, "--lr", "1e30", "--checkpoint-every", "1")) == 2
    err = capsys.readouterr().err
    assert "loss became" in err and "last good checkpoint" in err
    state = torch.load(run / "checkpoint.pt", weights_only=False)
    assert 1 <= state["step"] < 50
    assert all(torch.isfinite(v).all() for v in state["model"].values() if v.is_floating_point())


@pytest.mark.parametrize("flag, patch, message", [
    ("--precision=bf16", ("bridgeplan.train.bf16_supported", lambda device: False), "has no bfloat16 kernels"),
    ("--compile", ("shutil.which", lambda name: None), "needs a C++ compiler"),
    ("--compile --process meanflow", ("shutil.which", lambda name: "/usr/bin/c++"), "Jacobian-vector product"),
])
def test_device_features_missing_are_refused_before_anything_is_written(tiny_dataset, tmp_path, capsys,
                                                                        monkeypatch, flag, patch, message):
    monkeypatch.setattr(*patch)
    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 2, *flag.split())) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and message in err[0], err
    assert not run.exists()


def test_bf16_training_learns_and_resumes_exactly(tiny_dataset, tmp_path):
    from bridgeplan.train import bf16_supported

    if not bf16_supported(torch.device("cpu")):
        pytest.skip("this CPU has no bfloat16 kernels")
    whole, split = tmp_path / "whole", tmp_path / "split"
    assert main(train_args(tiny_dataset, whole, 6, "--precision", "bf16")) == 0
    assert main(train_args(tiny_dataset, split, 3, "--precision", "bf16")) == 0
    assert main(train_args(tiny_dataset, split, 6, "--precision", "bf16", "--resume")) == 0
    (m1, e1, s1), (m2, e2, s2) = weights(whole), weights(split)
    assert s1 == s2 == 6 and all(torch.equal(m1[k], m2[k]) and torch.equal(e1[k], e2[k]) for k in m1)
    # the weights stay float32 (autocast computes in bfloat16, the optimizer updates float32 weights)
    assert all(v.dtype == torch.float32 for v in m1.values() if v.is_floating_point())
    fp32 = tmp_path / "fp32"
    assert main(train_args(tiny_dataset, fp32, 6)) == 0
    assert any(not torch.equal(m1[k], weights(fp32)[0][k]) for k in m1)  # bf16 did compute differently


def test_losses_are_read_back_every_log_interval_off_the_cpu(tiny_dataset, tmp_path, monkeypatch, capsys):
    """On a GPU the loop reads the losses back every log_every steps (one host-device wait each), not every step;
    the CPU is made to behave so here, and the reads (stacks of losses) are counted."""
    import bridgeplan.train as train_module

    assert train_module.loss_check_every(torch.device("cuda"), 50) == 50
    assert train_module.loss_check_every(torch.device("cpu"), 50) == 1
    monkeypatch.setattr(train_module, "loss_check_every", lambda device, log_every: log_every)
    reads = []
    real_stack = torch.stack
    monkeypatch.setattr(train_module.torch, "stack",
                        lambda ts, *a, **k: reads.append(len(ts)) or real_stack(ts, *a, **k))
    assert main(train_args(tiny_dataset, tmp_path / "run", 10, "--log-every", "4", "--checkpoint-every", "100")) == 0
    assert reads == [4, 4, 2]  # at steps 4 and 8 (logged), then the last two before the final save
    # a loss that blows up between two reads (after the first update) is reported at its own step, never saved
    reads.clear()
    run = tmp_path / "nan"
    assert main(train_args(tiny_dataset, run, 50, "--lr", "1e30", "--log-every", "4", "--checkpoint-every",
                           "4")) == 2
    err = capsys.readouterr().err
    assert "loss became" in err and "at step 2;" in err and "before any checkpoint" in err, err
    assert reads == [4] and not (run / "checkpoint.pt").exists()
