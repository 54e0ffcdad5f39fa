"""The ``bridgeplan`` command: the subcommands of :mod:`bridgeplan.commands`, and those that run studies
(``study``) and ship their planners (``planners``), which stand on :mod:`bridgeplan.studies`."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from bridgeplan import commands
from bridgeplan.errors import BridgeplanError
from bridgeplan.option_groups import Output, Progress
from bridgeplan.options import add_command, opt, positive, shared


@dataclass(kw_only=True)
class Root:
    root: str | None = opt(None, "the repository root (holds studies/ and docs/results/; default: the git top-level of "
                                 "the current directory, else the current directory)")


@dataclass(kw_only=True)
class StudyListOptions:
    root: str | None = shared(Root, "root")


@dataclass(kw_only=True)
class StudyReportOptions:
    names: list[str] = opt([], "studies (names or files; default: all)", positional=True, nargs="*", metavar="NAME")
    check: bool = opt(False, "write nothing; exit 2 when a committed report differs from what its study generates")
    root: str | None = shared(Root, "root")


@dataclass(kw_only=True)
class StudyFile:
    file: str = opt(help="the study file (or a study's name)")


@dataclass(kw_only=True)
class StudyRunOptions:
    file: str = shared(StudyFile, "file")
    dry_run: bool = opt(False, "list what would be trained and evaluated, and its cost")
    quick: bool = opt(False, "a smaller scale (2 seeds, a tenth of the steps, 20 episodes) into results/quick/NAME; "
                             "not the committed scale")
    backend: str = opt("local", "local (this machine) or ray (each unit a task of a Ray cluster, a grid's runs and "
                                "an evaluation study's units alike)")
    workers: int | None = opt(None, "local backend: parallel jobs, a grid's runs or an evaluation study's units (a "
                                    "training seed and the runs its evaluations read; default: the study's)")
    ray_address: str | None = opt(None, "the ray cluster's address")
    no_progress: bool = shared(Progress, "no_progress")
    root: str | None = shared(Root, "root")


@dataclass(kw_only=True)
class StudyImportOptions:
    file: str = shared(StudyFile, "file")
    eval_json: list[str] | None = opt(None, "evaluation JSONs to import instead, each an evaluation that --experiment "
                                            "declares", metavar="FILE")
    experiment: str | None = opt(None, "with --eval-json: the study's experiment they belong to (NAME-validation: its "
                                       "validation split)")
    root: str | None = shared(Root, "root")


@dataclass(kw_only=True)
class StudyExportOptions:
    file: str = shared(StudyFile, "file")
    root: str | None = shared(Root, "root")


def _add_study_commands(sub) -> None:
    p = sub.add_parser("study", help="run a study file (studies/NAME.toml) and regenerate its reports",
                       description="Studies: one declarative file per campaign, at the repository root's studies/.")
    study = p.add_subparsers(dest="study_command", required=True)
    add_command(study, "list", StudyListOptions, _cmd_study_list,
                help="each study: its file, what it trains, the reports it makes and what they feed")
    add_command(study, "report", StudyReportOptions, _cmd_study_report,
                help="regenerate the studies' reports from the committed results (trains nothing)")
    add_command(study, "run", StudyRunOptions, _cmd_study_run,
                help="train and evaluate what the study's store is missing (resumable)")
    add_command(study, "import", StudyImportOptions, _cmd_study_import,
                help="load a study's committed rows (docs/results/DATA/results.csv, any schema) into its store, so "
                     "that `study run` computes only what they lack; or evaluation JSONs (`eval --json`) as rows of "
                     "one of its experiments")
    add_command(study, "export", StudyExportOptions, _cmd_study_export,
                help="a study's store (results/NAME) into its committed folder docs/results/DATA: results.csv, "
                     "report.md and a figure per experiment")


def _cmd_study_list(o: StudyListOptions) -> int:
    from bridgeplan.studies import find_root, generators, load_studies

    root = find_root(o.root)
    reports = generators.load(root)
    studies = load_studies(root)
    for s in studies.values():
        makes = [f"docs/results/{s.data_dir}/results.csv ({', '.join(dict.fromkeys(e.name for e in s.experiments))})"
                 ] if s.experiments else []
        folders = dict.fromkeys(e.out.split("/")[0] for e in s.evaluations)
        commands = dict.fromkeys(e.command for e in s.evaluations)
        makes += [f"docs/results/{f}/ ({', '.join(commands)} JSONs)" for f in folders]
        makes += [f"uses {', '.join(s.uses)}"] if s.uses or not makes else []
        for r in s.reports:
            feeds = reports[r.generator].feeds
            makes.append(f"docs/results/{r.output}" + (f" (feeds {', '.join(feeds)})" if feeds else ""))
        print(f"{s.name}\t{s.file}\t" + "; ".join(makes))
    return _report_broken(studies, [])


def _report_broken(studies, names: list[str]) -> int:
    """A study command over every study (no ``names``) does the others' work, then says which files are broken:
    one ``error:`` line each, exit 2; 0 when none is."""
    if names:
        return 0
    for error in studies.broken.values():
        print(f"error: {error}", file=sys.stderr)
    return 2 if studies.broken else 0


def _cmd_study_report(o: StudyReportOptions) -> int:
    from bridgeplan.studies import find_root, load_studies, select

    root = find_root(o.root)
    studies = load_studies(root)
    return _reports(root, studies, o.names, select(studies, o.names, root), o.check)


def _reports(root: Path, studies, names: list[str], chosen: list, check: bool) -> int:
    """Regenerate (or, ``check``, verify) the reports, provenance files and generated blocks of the ``chosen``
    studies (every study when no ``names`` were given) from the committed rows; 2 when one differs."""
    from bridgeplan.files import atomic_write_text
    from bridgeplan.studies import generators
    from bridgeplan.studies.export import provenance, provenance_path, stale_rows

    found = generators.load(root)
    results = root / "docs" / "results"
    texts = {}  # file (relative to root) -> (the studies that change it, text): nothing written unless all render
    for s in chosen:
        record = provenance(s, root)
        if record is not None:
            texts[provenance_path(s)] = ([s.name], record)
        for r in s.reports:
            generator = found[r.generator]
            texts[f"docs/results/{r.output}"] = ([s.name], generator.render(results))
            for feed in generator.feeds:  # the tables the README and docs show between the generator's markers
                names, current = texts.get(feed, ([], _read_or_empty(root / feed)))
                filled = generator.fill_blocks(current, results)
                if filled is not None:
                    texts[feed] = (names + [s.name] if filled != current else names, filled)
    benches = {}  # bench.md -> its bench.json: every study's command remakes them, as `bridgeplan bench` wrote them
    if not names:
        from bridgeplan.bench.markdown import committed_markdown

        for path in sorted(results.rglob("bench.json")):
            benches[str(path.with_name("bench.md").relative_to(root))] = path.relative_to(root)
            texts[str(path.with_name("bench.md").relative_to(root))] = ([], committed_markdown(path))
    differ = 0
    for output, (makers, text) in texts.items():
        name = ", ".join(makers) or "its studies"
        made_by = f"{benches[output]} (run bridgeplan study report)" if output in benches else (
            f"{name} (run bridgeplan study report {name})")
        path = root / output
        if check:
            if not path.exists() or path.read_text() != text:
                print(f"error: {output} differs from what {made_by.replace(' (', ' generates (', 1)}",
                      file=sys.stderr)
                differ += 1
        elif not path.exists() or path.read_text() != text:
            atomic_write_text(path, text)
            print(f"wrote {output}")
    if check:  # the committed rows were trained as their studies declare today
        for s in chosen:
            for line in stale_rows(s, root):
                print(f"error: {line}", file=sys.stderr)
                differ += 1
    fed = [output for output in texts if any(output in found[r.generator].feeds for s in chosen
                                             for r in s.reports)]
    provenances = sum(output.endswith("/study.json") for output in texts)
    reports = len(texts) - provenances - len(fed) - len(benches)
    if check and not differ:
        blocks = f", the generated blocks in {', '.join(fed)}" if fed else ""
        pages = f" and {len(benches)} bench pages" if benches else ""
        print(f"{reports} reports, {provenances} provenance files{blocks}{pages} match their studies and benches")
    return max(2 if differ else 0, _report_broken(studies, names))


def _read_or_empty(path: Path) -> str:
    return path.read_text() if path.exists() else ""


def _cmd_study_run(o: StudyRunOptions) -> int:
    from bridgeplan.studies import find_root, generators, load_studies, parse_study, select
    from bridgeplan.studies.plan import (
        QUICK_NOTE,
        Scale,
        check_reports,
        check_run,
        describe_missing,
        quick_table,
        results_dir,
        run_study,
        with_used,
    )

    root = find_root(o.root)
    studies = load_studies(root)
    if Path(o.file).is_file() and not any((root / s.file).resolve() == Path(o.file).resolve()
                                              for s in studies.values()):
        reports = generators.load(root)
        study = parse_study(o.file, generators=reports)
        check_reports(study, studies, reports)
    else:
        study = select(studies, [o.file], root)[0]
    scale = Scale("quick" if o.quick else "committed")
    if o.workers is not None:
        positive("--workers", o.workers)
    chain = with_used(study, studies)  # the studies whose rows its reports read first: one command makes them all
    check_run(chain, root, scale, o.backend, o.dry_run)
    if o.dry_run:
        print("\n".join(line for s in chain for line in describe_missing(s, root, scale)))
        return 0
    for s in chain:
        added = run_study(s, root, scale, backend=o.backend, workers=o.workers, ray_address=o.ray_address,
                          progress=not o.no_progress, note=lambda text: print(f"note: {text}", file=sys.stderr))
        if s.experiments or s.evaluations:
            print(f"{s.name}: {added} new results in {results_dir(s, root, scale)}"
                  + ("" if scale.committed else f" [{QUICK_NOTE}]"))
    if scale.committed:
        print(f"next: `bridgeplan study export {study.name}` writes these rows into docs/results and regenerates every "
              f"report from them (then `git diff` compares them with the committed ones)")
        return 0
    for s in chain:
        if lines := quick_table(s, root):
            print(f"\n{s.name} at the quick scale, beside its committed rows [{QUICK_NOTE}]:\n" + "\n".join(lines))
    stored = [s for s in chain if s.experiments]
    if stored:
        print(f"next: `bridgeplan report --results {results_dir(stored[-1], root, scale).relative_to(root)}` draws "
              f"every snapshot's figures and tables")
    return 0


def _cmd_study_import(o: StudyImportOptions) -> int:
    from bridgeplan.experiments.store import KEY as KEY_NAMES
    from bridgeplan.experiments.store import ResultsStore, key_of, read_csv_rows, read_eval_json_rows
    from bridgeplan.paths import store_path
    from bridgeplan.studies import find_root, load_studies, select
    from bridgeplan.studies.plan import Scale, missing, results_dir

    root = find_root(o.root)
    study = select(load_studies(root), [o.file], root)[0]
    if (o.eval_json is None) != (o.experiment is None):
        raise BridgeplanError("--eval-json and --experiment go together")
    if o.eval_json is None and not study.experiments and study.evaluations:  # the committed JSONs, copied
        from bridgeplan.studies.export import copy_jsons

        written = copy_jsons(study, root / "docs" / "results", results_dir(study, root, Scale()))
        print(f"{study.name}: {len(written)} evaluation JSONs copied into {results_dir(study, root, Scale())}")
        return 0
    if o.eval_json is None:
        source = root / "docs" / "results" / study.data_dir / "results.csv"
        if not study.experiments or not source.exists():
            raise BridgeplanError(f"study {study.name} has no committed rows to import "
                                  f"(no {source.relative_to(root)})")
        rows = read_csv_rows(source)  # the whole file checked before the store is touched
        source = source.relative_to(root)
    else:
        declared = missing(study, root).declared
        if o.experiment not in declared:
            raise BridgeplanError(f"study {study.name} has no experiment {o.experiment!r} (it has: "
                                  f"{', '.join(sorted(declared)) or 'none'})")
        rows = read_eval_json_rows(o.eval_json, o.experiment)
        for path, (row, _) in zip(o.eval_json, rows):
            if key_of(row) not in declared[o.experiment]:
                raise BridgeplanError(f"{path}: not an evaluation that {o.experiment} of {study.file} declares "
                                      f"({', '.join(f'{k}={v}' for k, v in zip(KEY_NAMES, key_of(row)))})")
        source = f"{len(rows)} evaluation JSONs"
    store = store_path(results_dir(study, root, Scale()))
    read, new = ResultsStore(store).import_rows(rows)
    print(f"{study.name}: {read} evaluations in {source}, {new} new in {store}")
    return 0


def _cmd_study_export(o: StudyExportOptions) -> int:
    from bridgeplan.studies import find_root, load_studies, select
    from bridgeplan.studies.export import export, exportable
    from bridgeplan.studies.plan import Scale, results_dir, with_used

    root = find_root(o.root)
    studies = load_studies(root)
    study = select(studies, [o.file], root)[0]
    # the study and those whose rows its reports read, as `study run` made them: each checked before any is written
    chain = exportable(with_used(study, studies), root, lambda s: results_dir(s, root, Scale()))
    for s in chain:
        for path in export(s, root, results_dir(s, root, Scale())):
            print(f"wrote {path.relative_to(root)}")
    code = _reports(root, studies, [], list(studies.values()), check=False)
    print("then `git diff docs/results README.md` shows how these rows compare with the committed ones")
    return code


@dataclass(kw_only=True)
class PlannersListOptions:
    json: bool = shared(Output, "json")


@dataclass(kw_only=True)
class PlannersExportOptions:
    study: str = opt("shipped", "the study whose used studies train the shipped planners")
    root: str | None = shared(Root, "root")
    out: str | None = shared(Output, "out")
    only: list[str] = opt([], "remake only these planners; the others keep their files and manifest entries",
                          metavar="NAME")


def _add_planners_commands(sub) -> None:
    p = sub.add_parser("planners", help="the shipped planners: trained weights that come with bridgeplan",
                       description="Shipped planners plan without training: give a name wherever a run directory "
                                   "goes (`bridgeplan eval medium`, `PlannerPolicy.from_run(\"medium\")`); a shipped "
                                   "policy (OGBench manipulation) is the dataset graph's low level over your own "
                                   "generated data (`bridgeplan graph --low NAME`, `PlannerPolicy.from_graph(NAME)`). "
                                   "Their scores: docs/results/shipped.md.")
    planners = p.add_subparsers(dest="planners_command")
    add_command(planners, "list", PlannersListOptions, _cmd_planners_list,
                help="each shipped planner with its manifest's facts (the default)")
    add_command(planners, "export", PlannersExportOptions, _cmd_planners_export,
                help="(re)make the shipped files and the manifest from a study's runs",
                description="--out: the output folder (default: ROOT/src/bridgeplan/shipped).")
    p.set_defaults(func=lambda args: _cmd_planners_list(PlannersListOptions()))


def _cmd_planners_list(o: PlannersListOptions) -> int:
    from dataclasses import asdict

    from bridgeplan import shipped

    entries = list(shipped.manifest().values())
    if o.json:
        print(json.dumps([asdict(e) for e in entries], indent=2))
        return 0
    if not entries:
        print("no shipped planners in this install")
        return 0
    for e in entries:
        use = " (bridgeplan graph --low NAME)" if e.kind == "policy" else ""
        print(f"{e.name}\t{e.maze}\t{e.method}{use}\tstep {e.step}\tseed {e.seed}\t{e.parameters} parameters\t"
              f"{e.bytes / 1e6:.2f} MB\tcode {e.code_version}\t{e.study}\tsha256 {e.sha256}")
    print("scores: docs/results/shipped.md (bridgeplan study report shipped)")
    return 0


def _cmd_planners_export(o: PlannersExportOptions) -> int:
    from bridgeplan import shipped
    from bridgeplan.studies import find_root
    from bridgeplan.studies.ship import ship

    root = find_root(o.root)
    for e in ship(root, o.study, Path(o.out) if o.out else None, tuple(o.only)):
        if o.only and e.name not in o.only:
            print(f"kept {e.file} ({e.name}: as shipped, sha256 {e.sha256[:12]}...)")
            continue
        print(f"wrote {e.file} ({e.name}: {e.method} on {e.maze}, {e.run} step {e.step}, code {e.code_version}, "
              f"{e.bytes} bytes, sha256 {e.sha256[:12]}...)")
    print(f"wrote {shipped.MANIFEST}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    return commands.build_parser(_add_study_commands, _add_planners_commands)


def main(argv: list[str] | None = None) -> int:
    return commands.run(build_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
