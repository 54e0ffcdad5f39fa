"""Counts of the package's shape (issue 41's goals), printed one per line: tests of an environment's name outside
envs/, imports that run back up the layers, import circles, evaluation entry points, CLI option declarations,
src/ lines. Reads the source tree only (``python scripts/shape_counts.py [SRC]``, default src/bridgeplan).

The layers, lowest first (a module may import its own layer and those below it): the first pattern a module's
dotted name starts with places it. Old and new names are both placed, so the script measures any commit."""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

LAYERS = [
    ("base", ("errors", "files", "locks", "device", "checkpoint", "workers", "layout", "paths", "options",
              "option_groups")),
    ("maths", ("trajectory", "normalizer", "nets", "processes")),
    ("data", ("data.stream", "data.windows", "data.npz", "data")),
    ("envs", ("envs", "maze", "ogbench_pointmaze")),
    ("planning", ("priors", "consistency", "planner")),
    ("training", ("config", "runs", "train", "gcbc", "gciql", "shipped")),
    ("decisions", ("replan", "graph", "hierarchy", "decisions", "evaluate", "render", "policy")),
    ("results", ("experiments", "analysis", "report", "bench", "studies", "eval_commands")),
    ("commands", ("commands", "gcbc_commands", "cli")),
]
# where the old tree's environment-specific modules lived outside its environment packages: data/ held Maze2D's
# generator and readers, ogbench_pointmaze/commands.py the OGBench commands
LAYER_OVERRIDES = {"data.generate": "envs", "data.minari_io": "envs", "data.d4rl_io": "envs", "data.datasets": "envs",
                   "data.info": "envs", "ogbench_pointmaze.commands": "commands", "analysis.keys": "results",
                   "experiments.store": "results"}
ENV_WORDS = {"maze2d", "ogbench", "ogbench-pointmaze", "pointmaze", "umaze", "medium", "large", "giant", "open",
             "teleport", "navigate", "stitch"}
NAME_PREDICATES = {"is_pointmaze", "require_family"}
NAME_SETS = {"MAZE_NAMES", "MAZES", "KINDS"}


def layer_of(module: str) -> int:
    if module == "bridgeplan":  # the package root holds the version only
        return 0
    name = module.removeprefix("bridgeplan.")
    if name in LAYER_OVERRIDES:
        return [n for n, _ in LAYERS].index(LAYER_OVERRIDES[name])
    for i, (_, prefixes) in enumerate(LAYERS):
        if any(name == p or name.startswith(p + ".") for p in prefixes):
            return i
    return len(LAYERS)  # unplaced (the package root): the top


def modules(src: Path) -> dict[str, Path]:
    out = {}
    for p in src.rglob("*.py"):
        parts = p.relative_to(src.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def import_graph(src: Path) -> dict[str, set[str]]:
    mods = modules(src)

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for name, path in mods.items():
        imported = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                imported.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                imported.update(f"{node.module}.{a.name}" for a in node.names)
        graph[name] = {m for m in map(resolve, imported) if m and m != name and m.startswith("bridgeplan")}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, recursive: the package is small)."""
    sys.setrecursionlimit(10_000)
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def _is_env_word(node) -> bool:
    if not (isinstance(node, ast.Constant) and isinstance(node.value, str)):
        return False
    v = node.value
    return v in ENV_WORDS or v.startswith(("pointmaze-", "ogbench ", "ogbench-"))


def name_tests(path: Path) -> list[int]:
    """Lines that test an environment's name: a comparison or membership with an environment word or name set,
    ``startswith`` of one, or a call of a name predicate."""
    lines = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            if any(_is_env_word(o) for o in operands) or any(
                    isinstance(o, (ast.Name, ast.Attribute)) and getattr(o, "id", getattr(o, "attr", "")) in NAME_SETS
                    for o in node.comparators):
                lines.append(node.lineno)
            elif any(isinstance(o, (ast.Tuple, ast.Set, ast.List)) and any(_is_env_word(e) for e in o.elts)
                     for o in node.comparators):
                lines.append(node.lineno)
        elif isinstance(node, ast.Call):
            f = node.func
            fname = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if fname in ("startswith", "endswith") and any(_is_env_word(a) or (
                    isinstance(a, ast.Name) and a.id.endswith("PREFIX")) for a in node.args):
                lines.append(node.lineno)
            elif fname in NAME_PREDICATES:
                lines.append(node.lineno)
    return sorted(set(lines))


def option_fields(text: str) -> list[str]:
    """The flags that options dataclasses declare (``name: T = opt(default, ...)``, bridgeplan.options); a field
    without a default, or ``positional=True``, is a positional argument, not a flag."""
    out = []
    for node in ast.walk(ast.parse(text)):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.value, ast.Call)
                and getattr(node.value.func, "id", None) == "opt"):
            keywords = {k.arg for k in node.value.keywords}
            if (node.value.args or "default" in keywords) and "positional" not in keywords:
                out.append("--" + node.target.id.replace("_", "-"))
    return out


def leaf_commands() -> list[str]:
    """Every leaf subcommand of the ``bridgeplan`` CLI, walked from its argparse parser (the package imported)."""
    import argparse

    from bridgeplan.cli import build_parser

    out = []

    def walk(parser, prefix):
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            out.append(prefix)
        for action in subs:
            for name, child in action.choices.items():
                walk(child, f"{prefix} {name}".strip())

    walk(build_parser(), "")
    return out


def main(src: Path) -> None:
    mods = modules(src)
    graph = import_graph(src)
    env_dirs = ("envs", "maze", "ogbench_pointmaze")
    tests = {}
    for name, path in mods.items():
        if name.removeprefix("bridgeplan.").split(".")[0] in env_dirs:
            continue
        found = name_tests(path)
        if found:
            tests[name] = found
    back = sorted((a, b) for a, deps in graph.items() for b in deps if layer_of(b) > layer_of(a))
    text = {name: path.read_text() for name, path in mods.items()}
    flags = re.findall(r"add_argument\(\s*\"(--[a-z0-9-]+)\"", "\n".join(text.values()))
    flags += re.findall(r"add_argument\(\s*f?\"(--\{name\})\"", "\n".join(text.values()))
    flags += [flag for t in text.values() for flag in option_fields(t)]
    evaluation_commands = [c for c in leaf_commands() if re.search(r"eval|oracle|expert|graph", c)]
    evaluate_functions = sorted(f"{n}.{m}" for n, t in text.items()
                                for m in re.findall(r"^def (evaluate\w*)\(", t, re.M))
    repeated = {f: flags.count(f) for f in sorted(set(flags)) if flags.count(f) > 1}
    print(f"name tests outside envs/: {sum(map(len, tests.values()))} in {len(tests)} modules")
    for name, lines in tests.items():
        print(f"  {name}: lines {', '.join(map(str, lines))}")
    print(f"imports back up the layers: {len(back)}")
    for a, b in back:
        print(f"  {a} -> {b}")
    print(f"import circles: {len(circles(graph))} {circles(graph)}")
    print(f"evaluation commands: {len(evaluation_commands)} {evaluation_commands}")
    print(f"evaluate* functions: {len(evaluate_functions)} {evaluate_functions}")
    print(f"flag declarations (add_argument, opt() fields): {len(flags)}; flags declared more than once: "
          f"{len(repeated)} "
          f"({sum(repeated.values())} declarations) {repeated}")
    lines = sum(len(t.splitlines()) for t in text.values())
    print(f"src lines: {lines} in {len(mods)} modules")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "src/bridgeplan").resolve())
