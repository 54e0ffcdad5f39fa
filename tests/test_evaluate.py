"""Evaluation and rendering through the real CLI on a tiny trained run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bridgeplan.cli import main
from tests.test_train import train_args


@pytest.mark.parametrize("process, nfe", [("ddpm", None), ("ddpm", 2), ("bridge", 1), ("bridge", None)])
def test_eval_json_fields(tiny_runs, tmp_path, capsys, process, nfe):
    out = tmp_path / "result.json"
    args = ["eval", str(tiny_runs[process]), "--episodes", "6", "--seed", "3", "--device", "cpu",
            "--out", str(out), "--json"]
    if nfe is not None:
        args += ["--nfe", str(nfe)]
    assert main(args) == 0
    printed = json.loads(capsys.readouterr().out)
    saved = json.loads(out.read_text())
    assert printed == saved
    assert saved["episodes"] == 6 and saved["seed"] == 3 and saved["maze"] == "umaze"
    assert saved["process"] == process
    assert saved["nfe"] == (nfe if nfe is not None else (6 if process == "ddpm" else 5))
    for convention in ("minari", "d4rl"):
        assert np.isfinite(saved["score"][convention]["mean"]) and saved["score"][convention]["se"] >= 0
    assert 0.0 <= saved["success_rate"]["mean"] <= 1.0
    assert saved["plan_ms_per_plan"] > 0
    assert sum(c["episodes"] for c in saved["per_start_cell"]) == 6
    assert saved["floor_line"]["prior"] == "line"
    # results carry no path of this machine: the run and its dataset are named by their directories
    assert saved["run"] == tiny_runs[process].name and saved["config"]["dataset"] == "umaze-tiny"
    assert str(tmp_path.parent.parent) not in out.read_text()
    if process == "bridge":
        assert saved["prior"] == "learned" and "prior_only_learned" in saved


def test_eval_is_reproducible(tiny_runs, tmp_path):
    outs = [tmp_path / f"{k}.json" for k in range(2)]
    for out in outs:
        assert main(["eval", str(tiny_runs["bridge"]), "--episodes", "4", "--device", "cpu",
                     "--out", str(out)]) == 0
    a, b = (json.loads(o.read_text()) for o in outs)
    assert a["return"] == b["return"] and a["score"] == b["score"]


@pytest.mark.parametrize("bad, message", [
    (["--nfe", "0"], "nfe"),
    (["--nfe", "6"], "nfe"),
    (["--episodes", "0"], "episodes must be positive"),
    (["--plan-batch", "0"], "--plan-batch must be positive"),
    (["--compile", "--frozen"], "choose one"),
])
def test_eval_bad_input(tiny_runs, capsys, bad, message):
    assert main(["eval", str(tiny_runs["bridge"]), "--device", "cpu", *bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0].lower()


@pytest.mark.parametrize("process", ["ddpm", "bridge"])
def test_eval_through_the_frozen_network_plans_the_same(tiny_runs, tmp_path, process):
    """``--frozen`` (the network traced and frozen) plans the eager network's plans: the same episodes, scores and
    floors; the JSON says which network planned."""
    rows = {}
    for frozen in (False, True):
        out = tmp_path / f"{process}-{frozen}.json"
        assert main(["eval", str(tiny_runs[process]), "--episodes", "4", "--nfe", "2", "--replan-every", "8",
                     "--device", "cpu", "--out", str(out), *(["--frozen"] if frozen else [])]) == 0
        rows[frozen] = json.loads(out.read_text())
    eager, frozen = rows[False], rows[True]
    assert eager["frozen"] is False and frozen["frozen"] is True
    for key in ("return", "score", "success_rate", "per_start_cell", "floor_line"):
        assert frozen[key] == eager[key]


def test_eval_missing_run(tmp_path, capsys):
    assert main(["eval", str(tmp_path / "nope")]) == 2
    assert "no checkpoint" in capsys.readouterr().err


def test_render_writes_pngs(tiny_runs, tmp_path):
    """Plans and executed states over the maze, prior/target pairs, and the first episode's video: each of its
    states replayed in gymnasium-robotics' renderer, every 4th and the last, 40 ms each; the point moves."""
    from PIL import Image

    from bridgeplan.evaluate import make_tasks

    out = tmp_path / "plan.png"
    assert main(["render", str(tiny_runs["bridge"]), "--episodes", "2", "--device", "cpu", "--out", str(out),
                 "--pairs", "--video", "--size", "24"]) == 0
    for path in (out, tmp_path / "plan-pairs.png"):
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    states = make_tasks("umaze", 2).episode_steps + 1
    with Image.open(out.with_suffix(".gif")) as gif:  # a frame as the one before it lengthens that one
        durations, frames = [], []
        for k in range(gif.n_frames):
            gif.seek(k)
            durations.append(gif.info["duration"])
            frames.append(np.asarray(gif.convert("RGB"), dtype=int))
        assert gif.size == (24, 24) and sum(durations) == 40 * (len(range(0, states, 4)) + ((states - 1) % 4 > 0))
    assert np.abs(frames[0] - frames[-1]).mean() > 0.1


def test_learned_prior_for_another_horizon_is_refused(tiny_dataset, tiny_runs, tmp_path, capsys):
    prior = tiny_runs["bridge"].parent / "prior"  # trained for horizon 32
    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 2, "--process", "bridge", "--prior", "learned",
                           "--prior-run", str(prior), "--horizon", "64")) == 2
    err = capsys.readouterr().err
    assert "trained for horizon 32, not 64" in err
    assert not (run / "checkpoint.pt").exists()


@pytest.mark.parametrize("command", ["eval", "render"])
def test_multi_task_refuses_data_that_misses_cells(tmp_path, capsys, command):
    """A run trained on 40 steps of data (a few cells of the U): Multi2D would draw goals where it has no data."""
    data, run = tmp_path / "few", tmp_path / "run"
    assert main(["data", "generate", "--maze", "umaze", "--steps", "40", "--seed", "1", "--out", str(data),
                 "--no-progress"]) == 0
    assert main(train_args(str(data), run, 1)) == 0
    capsys.readouterr()
    out = tmp_path / ("r.json" if command == "eval" else "r.png")
    assert main([command, str(run), "--episodes", "2", "--device", "cpu", "--multi-task", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "never visits" in err[0] and not out.exists()
    assert main([command, str(run), "--episodes", "2", "--device", "cpu", "--out", str(out)]) == 0  # single-task


def test_multi_task_on_covering_data_runs(tiny_runs, tmp_path):
    out = tmp_path / "r.json"
    assert main(["eval", str(tiny_runs["ddpm"]), "--episodes", "2", "--device", "cpu", "--multi-task",
                 "--out", str(out)]) == 0
    assert json.loads(out.read_text())["multi_task"] is True
