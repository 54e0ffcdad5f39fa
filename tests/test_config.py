"""One definition per method: the process object is the config that training, sweeps, evaluation,
reports and the bench ask; defaults that follow the maze; threads."""

from __future__ import annotations

import dataclasses
import json
import os
import warnings

import pytest
import torch

from bridgeplan import config as cfg
from bridgeplan.device import configure_threads
from bridgeplan.envs.maze2d.datasets import load_stream
from bridgeplan.errors import BridgeplanError
from bridgeplan.experiments.grids import RunSpec, get_experiment
from bridgeplan.experiments.runner import SweepSettings, _train_config
from bridgeplan.experiments.store import COLUMNS, KEY
from bridgeplan.processes import DDPM, PROCESSES, Bridge, parse_process_params, process_from_dict
from bridgeplan.report import method_label


@pytest.mark.parametrize("name", sorted(PROCESSES))
def test_every_process_round_trips_through_its_dict(name):
    process = PROCESSES[name]()
    assert process_from_dict(json.loads(json.dumps(process.to_dict()))) == process


def test_a_ddpm_saved_by_bridgeplan_0_1_still_loads():
    # 0.1 saved one ProcessConfig for every process, the bridge's fields included
    assert process_from_dict({"name": "ddpm", "steps": 16, "beta_max": 1.0, "ot_ode": False}) == DDPM(16)


def test_labels_and_run_names_say_what_was_trained():
    assert DDPM(16).label("gaussian") == "DDPM"
    assert DDPM(16, sampler="ddim").label("gaussian") == "DDPM"  # how it is sampled is not what was trained
    assert Bridge().label("line") == "bridge (line)"
    assert Bridge(beta_max=0.3, consistent=True).label("line") == "bridge (line; beta_max=0.3; consistent=True)"
    base = cfg.preset_config("umaze", "cpu-small", process=Bridge(16), prior="line")
    assert base.run_name() == "umaze-bridge-line-N16-H128-cpu-small-s0"  # the names of earlier runs are kept
    variant = dataclasses.replace(base, process=Bridge(16, beta_max=0.3, ot_ode=True))
    assert variant.run_name() == "umaze-bridge-line-N16-beta_max0.3-ot_ode-H128-cpu-small-s0"
    assert cfg.preset_config("umaze", "cpu-small").run_name() == "umaze-ddpm-N16-H128-cpu-small-s0"
    ablation = dataclasses.replace(base, process=Bridge(16, predict="x0", weighting="uniform"), hold_share=0.5)
    assert ablation.run_name() == "umaze-bridge-line-N16-predictx0-weightinguniform-hold0.5-H128-cpu-small-s0"
    assert ablation.label() == "bridge (line; predict=x0; weighting=uniform), hold 0.5"


def test_a_process_without_a_prior_refuses_one():
    with pytest.raises(BridgeplanError, match="DDPM starts from Gaussian noise"):
        cfg.preset_config("umaze", "cpu-small", prior="line")
    with pytest.raises(BridgeplanError, match="DDPM starts from Gaussian noise"):
        RunSpec(DDPM(16), "learned")
    with pytest.raises(BridgeplanError, match="unknown prior"):
        cfg.preset_config("umaze", "cpu-small", process=Bridge(), prior="straight")


def test_config_round_trip_keeps_the_process():
    config = cfg.preset_config("medium", "cpu-small", process=Bridge(16, beta_max=0.3, consistent=True), prior="line")
    again = cfg.from_dict(cfg.TrainConfig, json.loads(json.dumps(cfg.to_dict(config))))
    assert again == config and again.process == Bridge(16, beta_max=0.3, consistent=True)


def test_cpu_small_trains_the_short_maze2d_plans_at_batch_256():
    """Medium's and large's short plans train at batch 256, lr 3e-3 (measured on score at equal wall-clock); umaze's
    128 states and OGBench's shapes keep batch 32, lr 1e-3; a flag still overrides it."""
    for maze, batch, lr in (("medium", 256, 3e-3), ("large", 256, 3e-3), ("umaze", 32, 1e-3),
                            ("pointmaze-medium-navigate-v0", 32, 1e-3)):
        config = cfg.preset_config(maze, "cpu-small")
        assert (config.batch_size, config.lr, config.precision) == (batch, lr, "fp32"), maze
    assert cfg.preset_config("medium", "cpu-small", batch_size=32, lr=1e-3).batch_size == 32
    assert cfg.preset_config("medium", "diffuser").batch_size == 32  # Diffuser's own settings are untouched


def test_replace_switches_the_process_and_keeps_its_steps():
    config = cfg.preset_config("umaze", "cpu-small")
    bridge = cfg.replace(config, process={"name": "bridge", "beta_max": 0.3}, prior="line")
    assert bridge.process == Bridge(16, beta_max=0.3)
    assert cfg.replace(bridge, process={"steps": 8}).process == Bridge(8, beta_max=0.3)
    with pytest.raises(BridgeplanError, match="bad parameters for process 'ddpm'"):
        cfg.replace(config, process={"beta_max": 0.3})


def test_process_params_from_the_command_line_are_typed_by_the_dataclass():
    assert parse_process_params("bridge", ["beta_max=0.3", "ot_ode=true", "steps=8"]) == {
        "beta_max": 0.3, "ot_ode": True, "steps": 8}
    with pytest.raises(BridgeplanError, match="takes a float"):
        parse_process_params("bridge", ["beta_max=big"])
    with pytest.raises(BridgeplanError, match="a field of ddpm"):
        parse_process_params("ddpm", ["beta_max=0.3"])


def test_a_sweep_trains_the_process_it_declares():
    """The sweep varies the bridge's parameters: the runner trains exactly the spec's process."""
    experiment = get_experiment("priors", steps=8, informed=Bridge(beta_max=0.3, ot_ode=True))
    specs = experiment.runs()
    assert {s.process for s in specs} == {Bridge(8, beta_max=0.3, ot_ode=True)}
    settings = SweepSettings(dataset="data", preset="cpu-small")
    configs = [_train_config(settings, spec, 0, "prior-run") for spec in specs]
    assert all(c.process == Bridge(8, beta_max=0.3, ot_ode=True) for c in configs)
    assert [c.prior_run for c in configs] == ["", "", "prior-run"]
    assert len({c.run_name() for c in configs}) == 3


def test_defaults_follow_the_maze():
    assert cfg.PriorTrainConfig(maze="medium").horizon == cfg.preset_config("medium", "diffuser").horizon == 256
    assert cfg.PriorTrainConfig(maze="large").horizon == 384
    with pytest.raises(BridgeplanError, match="horizon 400 does not fit umaze"):
        cfg.preset_config("umaze", "cpu-small", horizon=400)


def test_eval_result_is_a_store_row_with_its_method(tiny_runs, tiny_dataset):
    from bridgeplan.evaluate import evaluate_run
    from bridgeplan.experiments.store import row_from_eval_json

    result = evaluate_run(tiny_runs["bridge"], episodes=2, nfe=1, device="cpu")
    row = row_from_eval_json(result.to_dict())
    assert set(row) <= set(COLUMNS) and set(KEY) <= set(row)
    # the row names its data by what it is: name, maze, size, version and the arrays' hash (no machine path)
    assert row["dataset"] == load_stream(tiny_dataset).identity()
    assert row["dataset"].startswith("umaze-tiny (umaze, ") and "sha256 " in row["dataset"]
    assert "/" not in row["dataset"]
    assert (row["process"], row["prior"], row["nfe"], row["episodes"]) == ("bridge", "learned", 1, 2)
    assert method_label(dict(row, config=json.dumps(row["config"]))) == "bridge (learned)"
    held = dict(row["config"], hold_share=0.5)  # a run trained on windows that wait is another method
    assert cfg.method_label(Bridge(), "learned", 0.5) == "bridge (learned), hold 0.5"
    assert method_label(dict(row, config=json.dumps(held))) == "bridge (learned), hold 0.5"
    assert result.to_dict()["method"] == "bridge (learned)"


def test_threads_default_to_one_on_a_cpu_and_warn_beyond_the_cores():
    before = torch.get_num_threads()
    try:
        assert configure_threads(0, torch.device("cpu")) == 1 == torch.get_num_threads()
        cores = os.cpu_count() or 1
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert configure_threads(cores + 1) == cores + 1
        assert any("more than this machine" in str(w.message) for w in caught)
        with pytest.raises(BridgeplanError, match="threads must be >= 0"):
            configure_threads(-1)
    finally:
        torch.set_num_threads(before)


def test_cli_warns_in_one_line_for_more_threads_than_cores(tiny_runs, tmp_path):
    import subprocess
    import sys

    cores = os.cpu_count() or 1
    command = ["eval", str(tiny_runs["ddpm"]), "--episodes", "2", "--nfe", "1", "--device", "cpu",
               "--threads", str(cores + 1), "--out", str(tmp_path / "r.json")]
    out = subprocess.run([sys.executable, "-m", "bridgeplan.cli", *command], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stderr.splitlines() == [f"warning: --threads {cores + 1} is more than this machine's {cores} cores: "
                                       "expect slower runs"]


def test_a_run_saved_by_bridgeplan_0_1_can_be_resumed():
    from bridgeplan.train import check_resumable

    config = cfg.preset_config("umaze", "cpu-small", dataset="d")
    saved = json.loads(json.dumps(cfg.to_dict(config)))
    saved["process"] = {"name": "ddpm", "steps": 16, "beta_max": 1.0, "ot_ode": False}  # 0.1's ProcessConfig
    check_resumable(saved, cfg.to_dict(config), "checkpoint.pt", cfg.TrainConfig)
    with pytest.raises(BridgeplanError, match="different config"):
        check_resumable(dict(saved, lr=0.5), cfg.to_dict(config), "checkpoint.pt", cfg.TrainConfig)
