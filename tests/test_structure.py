"""The package's modules import each other without circles: each layer (environment, data, processes, planner,
training, evaluation, the commands, studies, the CLI) stands only on those below it, lazy imports included."""

from __future__ import annotations

import ast
from pathlib import Path

import bridgeplan

PACKAGE = Path(bridgeplan.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> the package's modules it imports anywhere in its text (the longest existing prefix of each
    imported name: ``from a.b import c`` is ``a.b.c`` when that is a module, else ``a.b``)."""
    modules = {_module_name(p): p for p in package.rglob("*.py")}

    def resolve(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for name, path in modules.items():
        imported = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                imported.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                imported.update(f"{node.module}.{a.name}" for a in node.names)
        graph[name] = {m for m in map(resolve, imported) if m and m != name}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan's algorithm, iterative)."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    out.append(sorted(component))
    return out


def test_circles_finds_a_loop_and_only_the_loop():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert circles(graph) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


def test_the_package_imports_without_circles():
    graph = import_graph()
    assert {"bridgeplan.cli", "bridgeplan.commands", "bridgeplan.studies.plan", "bridgeplan.runs"} <= set(graph)
    assert "bridgeplan.gcbc" in graph["bridgeplan.studies.jobs"]  # lazy imports are read too
    assert circles(graph) == []


def environment_name_tests(package: Path = PACKAGE) -> list[str]:
    """``module:line`` of every comparison, membership or ``startswith``/``endswith`` test against an environment
    name's text (a Maze2D maze, an OGBench maze or prefix, a spec file's suffix) outside ``bridgeplan.envs``."""
    from bridgeplan.envs.maze2d.grids import MAZE_NAMES
    from bridgeplan.envs.ogbench_pointmaze.names import KINDS, MAZES

    names = {*MAZE_NAMES, *MAZES, *KINDS, "pointmaze", "pointmaze-", ".toml"}
    out = []
    for path in sorted(package.rglob("*.py")):
        parts = path.relative_to(package.parent).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        if module.startswith("bridgeplan.envs"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            texts = []
            if isinstance(node, ast.Compare):
                texts = [n for n in (node.left, *node.comparators) if isinstance(n, (ast.Constant, ast.Tuple,
                                                                                     ast.List, ast.Set))]
                texts = [c for n in texts for c in ([n] if isinstance(n, ast.Constant) else n.elts)]
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and node.func.attr in ("startswith", "endswith")):
                texts = node.args
            if any(isinstance(t, ast.Constant) and t.value in names for t in texts):
                out.append((module, node.lineno))
    return [f"{m}:{line}" for m, line in sorted(out)]


def test_nothing_outside_envs_tests_an_environments_name(tmp_path):
    """The rest of the package asks the family (``bridgeplan.envs.family_of``) instead."""
    assert environment_name_tests() == []
    (tmp_path / "bridgeplan").mkdir()
    (tmp_path / "bridgeplan" / "evaluate.py").write_text('if maze == "umaze" or env.startswith("pointmaze-"):\n'
                                                         '    pass\nif name in ("large", "x"):\n    pass\n')
    assert environment_name_tests(tmp_path / "bridgeplan") == ["bridgeplan.evaluate:1", "bridgeplan.evaluate:1",
                                                               "bridgeplan.evaluate:3"]


LAYERS = (
    ("errors", "files", "paths", "locks", "device", "progress", "workers", "shipped", "options", "option_groups"),
    ("trajectory", "normalizer", "data", "nets", "processes", "checkpoint"),
    ("envs",),
    ("priors", "consistency", "planner", "replan", "graph", "config", "runs", "train"),
    ("evaluate", "hierarchy", "gcbc", "gciql", "policy", "render"),
    ("experiments", "analysis", "studies", "bench", "report", "eval_commands"),
    ("commands", "cli", "gcbc_commands"),
)
"""The package's layers, lowest first, by the name below ``bridgeplan.`` (a module's own or its folder's)."""


def layer(module: str) -> int | None:
    top = module.split(".")[1] if "." in module else None
    return next((i for i, names in enumerate(LAYERS) if top in names), None)


def test_every_module_has_a_layer_and_stands_on_those_below():
    graph = import_graph()
    assert [m for m in graph if m != "bridgeplan" and layer(m) is None] == []
    back = {(m, t) for m, targets in graph.items() for t in targets
            if layer(m) is not None and layer(t) is not None and layer(t) > layer(m)}
    assert back == set()  # the study runner calls the evaluation commands' functions, not the CLI
