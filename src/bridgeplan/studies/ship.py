"""The shipped planners (:mod:`bridgeplan.shipped`) made from a study's runs: ``bridgeplan planners export``.

Here, not in :mod:`bridgeplan.shipped`, because making them reads studies, while reading them (any command given a
shipped planner's name) must not."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

from bridgeplan import config as cfg
from bridgeplan.checkpoint import load_checkpoint, save_checkpoint
from bridgeplan.envs import family_of
from bridgeplan.errors import BridgeplanError
from bridgeplan.evaluate import make_tasks
from bridgeplan.experiments.runner import _train_config
from bridgeplan.files import atomic_write_text
from bridgeplan.paths import runs_dir, snapshot_path
from bridgeplan.runs import build_model
from bridgeplan.shipped import MANIFEST, STUDY, ShippedPlanner, manifest, sha256
from bridgeplan.studies import load_studies, select
from bridgeplan.studies.plan import Scale, build_experiment, results_dir, sweeps


def ship(root: Path, study_name: str = STUDY, out: Path | None = None,
         only: tuple[str, ...] = ()) -> list[ShippedPlanner]:
    """Make the shipped files from ``study_name``'s used studies (each trains one run: one method, one seed) in
    ``root/results``: per study, its run's final snapshot reduced to what inference needs, named after the maze, and
    the manifest; into ``out`` (default ``root/src/bridgeplan/shipped``). Refuses a run short of its steps, trained
    at uncommitted code, or whose final snapshot has no committed rows in the study's results.csv.

    ``only``: remake just these planners (by name); the others keep their files and manifest entries, which must be
    in ``out`` and intact (so one maze is re-shipped without the other mazes' runs at hand)."""
    import torch

    root = Path(root).resolve()
    out = Path(out) if out else root / "src" / "bridgeplan" / "shipped"
    studies = load_studies(root)
    top = select(studies, [study_name], root)[0]
    if not top.uses:
        raise BridgeplanError(f"study {top.name} uses no studies: nothing to ship")
    kept = _kept(out, [studies[u].dataset.maze for u in top.uses], only)
    entries = []
    for used in top.uses:
        study = studies[used]
        if study.dataset.maze in kept:
            entries.append(kept[study.dataset.maze])
            continue
        runs = {r for i in range(len(study.experiments)) for r in build_experiment(study, i).runs()}
        if len(runs) != 1 or len(study.training.seeds) != 1:
            raise BridgeplanError(f"study {study.name} trains {len(runs)} methods x {len(study.training.seeds)} "
                                  f"seeds: a shipped planner's study trains one run")
        spec, seed = runs.pop(), study.training.seeds[0]
        settings = sweeps(study, root)[0].settings
        config = _train_config(settings, spec, seed, "")
        run_dir = runs_dir(results_dir(study, root, Scale())) / config.run_name()
        path = snapshot_path(run_dir, study.training.steps)
        if not path.exists():
            raise BridgeplanError(f"study {study.name}: no snapshot at step {study.training.steps} in {run_dir} "
                                  f"(run `bridgeplan study run {study.file}` first)")
        state = load_checkpoint(path)
        version = state.get("code_version", "")
        if not version or version.endswith(".dirty"):
            raise BridgeplanError(f"{path} was trained at code {version or 'unknown'}: ship only runs trained at a "
                                  f"committed code version")
        rows_csv = Path("docs") / "results" / study.data_dir / "results.csv"
        _check_rows(root / rows_csv, config.run_name(), state["step"])
        if any(s.multi_task for e in study.experiments for s in e.series):
            family_of(study.dataset.maze).check_run_data(make_tasks(study.dataset.maze, 1, multi_task=True),
                                                         state["config"]["dataset"])  # raises if a cell is unvisited
        loaded = cfg.from_dict(cfg.TrainConfig, state["config"])
        model = build_model(loaded)
        model.load_state_dict(state["ema"])  # the weights fit the config
        portable = dict(state["config"], dataset=Path(state["config"]["dataset"]).name)
        shipped = {"kind": "planner", "config": portable, "normalizer": state["normalizer"], "step": state["step"],
                   "elapsed_seconds": state["elapsed_seconds"], "code_version": version,
                   "ema": {k: v.detach().to(torch.float32).contiguous() for k, v in state["ema"].items()},
                   "dataset_covers_every_cell": True, "shipped": study.dataset.maze}
        name = study.dataset.maze
        file = out / f"{name}.pt"
        save_checkpoint(file, shipped)
        entries.append(ShippedPlanner(
            name=name, maze=study.dataset.maze, method=loaded.label(), process=loaded.process.name,
            prior=loaded.prior, study=str(study.file), rows=str(rows_csv), run=config.run_name(), seed=seed,
            step=int(state["step"]), code_version=version, dataset=portable["dataset"],
            parameters=sum(p.numel() for p in model.parameters()), file=file.name, bytes=file.stat().st_size,
            sha256=sha256(file)))
    atomic_write_text(out / MANIFEST, json.dumps({
        "made_by": f"bridgeplan planners export --study {top.name}",
        "planners": [asdict(e) for e in entries]}, indent=2) + "\n")
    return entries


def _kept(out: Path, names: list[str], only: tuple[str, ...]) -> dict[str, ShippedPlanner]:
    """The manifest entries in ``out`` of the planners not in ``only`` (none when ``only`` is empty), each checked
    against its file before anything is written."""
    if not only:
        return {}
    unknown = sorted(set(only) - set(names))
    if unknown:
        raise BridgeplanError(f"no shipped planner named {', '.join(unknown)}: choose from {', '.join(names)}")
    shipped = manifest(out)
    kept = {}
    for name in names:
        if name in only:
            continue
        entry = shipped.get(name)
        if entry is None or not (out / entry.file).exists() or sha256(out / entry.file) != entry.sha256:
            raise BridgeplanError(f"{name} would be kept as shipped, but {out} has no intact {name} file in its "
                                  f"manifest: export it too (leave it out of --only)")
        kept[name] = entry
    return kept


def _check_rows(csv_path: Path, run_name: str, step: int) -> None:
    """The committed rows of ``csv_path`` include ``run_name``'s evaluations at ``step``."""
    import csv

    if not csv_path.exists():
        raise BridgeplanError(f"no committed rows at {csv_path}: run the study and export its store "
                              f"(`bridgeplan study export STUDY`) first")
    with open(csv_path) as f:
        found = [r for r in csv.DictReader(f) if r["run_name"] == run_name and int(r["step"]) == int(step)]
    if not found:
        raise BridgeplanError(f"{csv_path} has no rows of {run_name} at step {step}: the file would ship unscored")
