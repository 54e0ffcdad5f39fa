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
    kept = _kept(out, [_name(studies[u]) for u in top.uses], only)
    entries = []
    for used in top.uses:
        study = studies[used]
        if _name(study) in kept:
            entries.append(kept[_name(study)])
            continue
        if study.runs:
            entries.append(_ship_policy(study, root, out))
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
        version = _committed_version(state, path)
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


def _name(study) -> str:
    """A shipped planner's name: its maze's (a grid study's), or its study's name after ``shipped-`` (a policy's:
    ``shipped-cube-single`` ships ``cube-single``)."""
    return study.name.removeprefix("shipped-") if study.runs else study.dataset.maze


def _committed_version(state: dict, path: Path) -> str:
    version = state.get("code_version", "")
    if not version or version.endswith(".dirty"):
        raise BridgeplanError(f"{path} was trained at code {version or 'unknown'}: ship only runs trained at a "
                              f"committed code version")
    return version


def _ship_policy(study, root: Path, out: Path) -> ShippedPlanner:
    """An evaluation study's one GCBC/GCIQL run (one training seed) as a shipped policy: its policy snapshot at the
    study's last step, its config naming the dataset's file alone and the identity of the data its committed graph
    rows were built over (which the user's own generated data must match). Refuses what :func:`ship` refuses."""
    from bridgeplan.gcbc import KIND, load_policy
    from bridgeplan.studies.jobs import jobs, run_dir

    if len(study.runs) != 1 or study.runs[0].trainer != "gcbc" or len(study.training.seeds) != 1:
        raise BridgeplanError(f"study {study.name} trains {len(study.runs)} runs x {len(study.training.seeds)} seeds: "
                              f"a shipped policy's study trains one GCBC or GCIQL run at one seed")
    run, seed = study.runs[0], study.training.seeds[0]
    run_path = run_dir(results_dir(study, root, Scale()), run.name, seed)
    path = snapshot_path(run_path, study.training.steps)
    if not path.exists():
        raise BridgeplanError(f"study {study.name}: no snapshot at step {study.training.steps} in {run_path} "
                              f"(run `bridgeplan study run {study.file}` first)")
    state = load_checkpoint(path)
    if state["kind"] != KIND:
        raise BridgeplanError(f"{path} is a {state['kind']} checkpoint, not a GCBC one")
    version = _committed_version(state, path)
    rows = [job.path for job in jobs(study, Path("results"), Path("docs") / "results", quick=False)]
    missing = [str(r) for r in rows if not (root / r).exists()]
    if missing:
        raise BridgeplanError(f"study {study.name} has no committed rows {', '.join(missing)}: run the study and "
                              f"export it (`bridgeplan study export {study.name}`) first")
    read = [json.loads((root / r).read_text()) for r in rows]
    scored = [r["low"] if "graph" in r else r for r in read]  # a graph row names its policy in "low"
    if any((s.get("run"), s.get("step")) != (run_path.name, state["step"]) for s in scored):
        raise BridgeplanError(f"{', '.join(map(str, rows))}: not all of {run_path.name} at step {state['step']}: the "
                              f"file would ship unscored")
    identities = {r["config"]["dataset_identity"] for r in read if "graph" in r}
    if len(identities) != 1:
        raise BridgeplanError(f"study {study.name}: its rows evaluate the dataset graph over {len(identities)} "
                              f"datasets: a shipped policy's study evaluates the graph over its run's data")
    name = _name(study)
    config = dict(state["config"], dataset=Path(state["config"]["dataset"]).name)
    file = out / f"{name}.pt"
    save_checkpoint(file, {k: state[k] for k in ("kind", "obs_dim", "action_dim", "step", "elapsed_seconds",
                                                 "code_version", "policy")}
                    | {"config": config, "shipped": name, "dataset_identity": identities.pop()})
    policy = load_policy(file)  # the file reads back as a policy
    return ShippedPlanner(
        name=name, maze=study.dataset.maze, method=f"the dataset graph over {policy.config.agent.upper()}",
        process=policy.config.agent, prior="", study=str(study.file), rows=str(Path(rows[0]).parent),
        run=run_path.name, seed=seed, step=int(state["step"]), code_version=version, dataset=config["dataset"],
        parameters=sum(p.numel() for p in policy.net.parameters()), file=file.name, bytes=file.stat().st_size,
        sha256=sha256(file), kind="policy", dataset_identity=policy.dataset_identity)


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
