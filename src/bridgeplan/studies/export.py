"""A study's committed folder, ``docs/results/DATA/``: what ``study export`` writes there from the study's store
(``results.csv``, ``report.md`` and a figure per experiment), and the provenance ``study.json`` that
``study report`` generates from the committed rows (``--check`` verifies it): the study file and its sha256, the
code versions that made the rows, the seeds and the number of evaluations.
"""

from __future__ import annotations

import csv
import hashlib
import json
from pathlib import Path

from bridgeplan.errors import BridgeplanError
from bridgeplan.studies.spec import Study, committed_csv

PROVENANCE = "study.json"


def provenance_path(study: Study) -> str:
    """The provenance file, relative to the repository root."""
    return f"docs/results/{study.data_dir}/{PROVENANCE}"


def provenance(study: Study, root: Path) -> str | None:
    """The text of the study's provenance file, from its study file and committed rows; None for a study that
    commits no rows of its own (it reads others')."""
    path = committed_csv(study, root)
    if not study.experiments or not path.exists():
        return None
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    record = {
        "study": str(study.file),
        "study_sha256": hashlib.sha256((Path(root) / study.file).read_bytes()).hexdigest(),
        "rows": f"docs/results/{study.data_dir}/results.csv",
        "evaluations": len(rows),
        "experiments": sorted({e for r in rows for e in (r.get("experiments") or r.get("experiment", "")).split()}),
        "training_seeds": sorted({int(r["seed"]) for r in rows}),
        "code_versions": sorted({r["code_version"] for r in rows if r.get("code_version")}),
    }
    return json.dumps(record, indent=2) + "\n"


NOT_DECLARED = {"dataset", "prior_run", "device", "threads", "log_every", "steps", "checkpoint_every", "minutes"}
"""Config fields a committed row may record otherwise than its study declares: where the data and the prior lay,
how it ran, and the snapshot's stage (a run trained in stages records each stage's steps)."""


def differences(declared: dict, recorded: dict) -> list[str]:
    """The fields of a row's ``recorded`` config (``config.to_dict`` form) that ``declared`` sets otherwise; of a
    nested one (the process, the model), the fields the row records (older rows lack fields added since)."""
    out = []
    for name, value in sorted(recorded.items()):
        if name in NOT_DECLARED or name not in declared:
            continue
        want = declared[name]
        if isinstance(value, dict) and isinstance(want, dict):
            want = {k: want.get(k) for k in value}
        was, now = json.dumps(value, sort_keys=True), json.dumps(want, sort_keys=True)
        if was != now:
            out.append(f"{name} {was} (the study now: {now})")
    return out


def stale_rows(study: Study, root: Path) -> list[str]:
    """Where the study's committed rows were trained otherwise than the study now declares (a preset's default
    changed under a study that does not pin it, say): one line per run and field; [] when they agree. The rows of
    its grids (docs/results/DATA/results.csv) and the JSONs of its one-run planner evaluations."""
    from bridgeplan import config as cfg
    from bridgeplan.experiments.runner import _train_config
    from bridgeplan.studies.jobs import jobs, train_config
    from bridgeplan.studies.plan import sweeps

    recorded: dict[str, dict] = {}  # run name -> its config as a row records it
    declared: dict[str, dict] = {}
    path = committed_csv(study, root)
    if study.experiments and path.exists():
        for sweep in sweeps(study, root):
            for seed in sweep.settings.seeds:
                for spec in sweep.experiment.runs():
                    config = _train_config(sweep.settings, spec, seed, "")
                    declared[config.run_name()] = cfg.to_dict(config)
        with path.open(newline="") as f:
            for r in csv.DictReader(f):
                recorded.setdefault(r["run_name"], json.loads(r["config"]))
    runs = {r.name: r for r in study.runs}
    results = Path(root) / "docs" / "results"
    for job in jobs(study, results, results, quick=False):
        if len(job.runs) != 1 or runs[job.runs[0]].trainer != "planner" or not job.path.exists():
            continue
        config = json.loads(job.path.read_text()).get("config") or {}
        name = f"{job.runs[0]}-s{job.seed}"
        if "process" in config:  # a planner's own run (not a graph's low level, recorded under "low")
            recorded.setdefault(name, config)
            declared[name] = cfg.to_dict(train_config(study, runs[job.runs[0]], job.seed, Path("dataset")))
    return [f"{study.file}: run {run}: rows trained with {d}" for run, config in sorted(recorded.items())
            if run in declared for d in differences(declared[run], config)]


def exportable(chain: list[Study], root: Path, store_dir) -> list[Study]:
    """The studies of ``chain`` (a study and those it uses) that have rows of their own, each checked to have them
    in its results (``store_dir(study)``) and to be writable into docs/results, before any is written."""
    own = [s for s in chain if s.experiments or s.evaluations]
    if not own:
        raise BridgeplanError(f"study {chain[-1].name} trains and evaluates nothing of its own, nor do the studies "
                              f"it uses: nothing to export")
    for s in own:
        _pairs(s, root, Path(store_dir(s)))
    return own


def _pairs(study: Study, root: Path, store_dir: Path) -> list[tuple[Path, Path]]:
    """What :func:`export` copies or writes: (source, target) pairs, the targets' folders writable; an error when the
    study has nothing to export."""
    from bridgeplan import paths
    from bridgeplan.experiments.store import stored_keys
    from bridgeplan.files import check_writable

    if not study.experiments and not study.evaluations:
        raise BridgeplanError(f"study {study.name} trains and evaluates nothing of its own: nothing to export")
    if not study.experiments:
        return _json_pairs(study, store_dir, Path(root) / "docs" / "results")
    store = paths.store_path(store_dir)
    if not store.exists():
        raise BridgeplanError(f"no results store at {store}; run `bridgeplan study run {study.file}` (or "
                              f"`study import`) first")
    if not stored_keys(store)[0]:  # read only, before the committed rows are overwritten
        raise BridgeplanError(f"{store} holds no evaluation yet")
    check_writable(committed_csv(study, root).parent, "committed results folder", folder=True)
    return [(store, committed_csv(study, root))]


def export(study: Study, root: Path, store_dir: Path) -> list[Path]:
    """The study's results (``store_dir``, its committed-scale results directory) into docs/results: its store as
    ``results.csv`` (every evaluation, one schema), ``report.md`` and a PNG per experiment in its committed folder,
    or its evaluation JSONs copied to their ``out`` paths (each atomically); the files written."""
    from bridgeplan.experiments.store import ResultsStore
    from bridgeplan.report import write_report

    pairs = _pairs(study, root, Path(store_dir))
    if not study.experiments:
        return copy_jsons(study, Path(store_dir), Path(root) / "docs" / "results")
    out = committed_csv(study, root).parent
    ResultsStore(pairs[0][0]).export_csv(out / "results.csv")
    titles = {e.name + suffix: e.title for e in study.experiments if e.title for suffix in ("", "-validation")}
    report = write_report(Path(store_dir), out, titles)
    return [out / "results.csv", report, *sorted(out.glob("*.png"))]


def copy_jsons(study: Study, source: Path, target: Path) -> list[Path]:
    """The study's evaluation JSONs that exist under ``source`` copied to the same ``out`` paths under ``target``
    (each atomically, every target folder checked first); the files written. None there: an error."""
    from bridgeplan.files import atomic_write_text

    pairs = _json_pairs(study, source, target)
    for path, out in pairs:
        atomic_write_text(out, path.read_text())
    return [out for _, out in pairs]


def _json_pairs(study: Study, source: Path, target: Path) -> list[tuple[Path, Path]]:
    """(the JSON under ``source``, where it goes under ``target``) for each evaluation JSON of the study that
    exists, every target folder checked writable; an error when none exists."""
    from bridgeplan.files import check_writable
    from bridgeplan.studies.jobs import jobs

    found = [job.path for job in jobs(study, source, source, quick=False) if job.path.exists()]
    if not found:
        raise BridgeplanError(f"no evaluation JSON of study {study.name} under {source}; run `bridgeplan study run "
                              f"{study.file}` (or `study import`) first")
    pairs = [(path, Path(target) / path.relative_to(source)) for path in found]
    for folder in dict.fromkeys(out.parent for _, out in pairs):
        check_writable(folder, "committed results folder", folder=True)
    return pairs
