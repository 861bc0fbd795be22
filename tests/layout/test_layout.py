"""The source tree as an installation sees it.

`pip install .` (not only the editable install the tests use) must carry every package of the
tree: a subpackage left out of `pyproject.toml` imports in the checkout and fails for a user.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from setuptools import find_packages

ROOT = Path(__file__).resolve().parents[2]


def _packages_in_tree() -> set[str]:
    """The packages as installed: generator/ and xlfuncs/ inside the namespace cmmwb (no folder)."""
    out = set()
    for top in ("generator", "xlfuncs"):
        for name in find_packages(str(ROOT), include=[top, top + ".*"]):
            out.add("cmmwb." + name)
    return out


def test_every_package_in_the_tree_is_installed():
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert setuptools["package-dir"] == {"cmmwb.generator": "generator", "cmmwb.xlfuncs": "xlfuncs"}
    assert not (ROOT / "cmmwb").exists()     # cmmwb is a namespace: the tree keeps its top level
    installed = set(setuptools["packages"])
    assert _packages_in_tree() <= installed, sorted(_packages_in_tree() - installed)
    assert installed <= _packages_in_tree(), sorted(installed - _packages_in_tree())
    assert {"cmmwb.xlfuncs.locator", "cmmwb.generator.importers"} <= installed


def _tree_name(dotted: str) -> str:
    """A module's name in the tree (``generator.x``) from its installed name (``cmmwb.generator.x``)."""
    return dotted.removeprefix("cmmwb.")


# --- the import graph: layers, no cycles, no private names across modules --------------------
#
# Built from the source text with `ast` only (nothing is imported): every Import/ImportFrom of a
# module of `generator` or `xlfuncs`, relative or absolute, at module level or inside a function,
# and every string constant that is exactly a module's dotted name (what importlib.import_module
# would be given), so that a dynamic import is a dependency too.

import ast  # noqa: E402

TASK_KINDS = ("pointcloud", "budget", "feature", "diagnosis", "characteristic")


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _project_modules(root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name -> file, for every module inside a package of `generator`/`xlfuncs`
    (package data such as generator/lo_addin or generator/examples is no package)."""
    out = {}
    for top in ("generator", "xlfuncs"):
        for path in sorted((root / top).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if not all((root.joinpath(*parts[:i]) / "__init__.py").is_file()
                       for i in range(1, len(parts))):
                continue
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]):
    """(imported project module, names taken from it, node) for each import in one module."""
    is_package = path.name == "__init__.py"
    package = name if is_package else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    for node in ast.walk(tree):
        if (isinstance(node, ast.Constant) and isinstance(node.value, str)
                and _tree_name(node.value) in modules):     # importlib.import_module("cmmwb.generator.x")
            yield _tree_name(node.value), [], node, None
        elif isinstance(node, ast.Import):
            for alias in node.names:
                target = _tree_name(alias.name)
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                if target:
                    yield target, [], node, alias
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = _tree_name(node.module or "")
            if source == "cmmwb":                  # `from cmmwb import xlfuncs`
                for alias in node.names:
                    if alias.name in modules:
                        yield alias.name, [], node, alias
                continue
            if source not in modules:
                continue
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                if sub in modules:                 # `from pkg import module`
                    yield sub, [], node, alias
                else:
                    yield source, [alias.name], node, alias


def _graph(root: Path = ROOT) -> dict[str, set[str]]:
    modules = _project_modules(root)
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, path in modules.items():
        for target, _names, _node, _alias in _imports(name, path, modules):
            if target != name:
                graph[name].add(target)
    return graph


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan): each is a set of
    modules that all import one another, directly or through the others."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def strongconnect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            strongconnect(v)
    return components


def find_cycles(root: Path = ROOT) -> list[tuple[list[str], list[str]]]:
    """For each strongly connected component of the import graph: one shortest cycle through
    its first module (a -> b -> ... -> a) and the component's modules."""
    graph = _graph(root)
    out = []
    for component in strongly_connected(graph):
        members = set(component)
        start = component[0]
        previous = {start: None}
        queue = [start]
        found = None
        while queue and found is None:
            v = queue.pop(0)
            for w in sorted(graph[v] & members):
                if w == start:
                    found = v
                    break
                if w not in previous:
                    previous[w] = v
                    queue.append(w)
        path = [start]
        v = found
        while v is not None and v != start:
            path.insert(1, v)
            v = previous[v]
        out.append((path + [start], component))
    return out


def private_uses(root: Path = ROOT) -> list[str]:
    """`from m import _x` and `m._x` where m is another module of the project."""
    modules = _project_modules(root)
    out = []
    for name, path in modules.items():
        bound: dict[str, str] = {}              # local name -> project module it is bound to
        for target, names, node, alias in _imports(name, path, modules):
            where = f"{path.relative_to(root)}:{node.lineno}"
            if target == name:
                continue
            for taken in names:
                if _is_private(taken):
                    out.append(f"{where}: from {target} import {taken}")
            if alias is None:
                continue
            if not names:
                if _is_private(target.rpartition(".")[2]):
                    out.append(f"{where}: imports private module {target}")
                if isinstance(node, ast.Import) and alias.asname is None:
                    bound[alias.name.partition(".")[0]] = alias.name.partition(".")[0]
                else:
                    bound[alias.asname or alias.name] = target
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and _is_private(node.attr)):
                continue
            chain = []
            value = node.value
            while isinstance(value, ast.Attribute):
                chain.insert(0, value.attr)
                value = value.value
            if not (isinstance(value, ast.Name) and value.id in bound):
                continue
            dotted = _tree_name(".".join([bound[value.id]] + chain))
            if dotted in modules and dotted != name:
                out.append(f"{path.relative_to(root)}:{node.lineno}: {dotted}.{node.attr}")
    return sorted(out)


def test_no_import_cycles():
    cycles = find_cycles()
    assert not cycles, "import cycles:\n" + "\n".join(
        f"{' -> '.join(cycle)}   (one of the cycles among: {', '.join(component)})"
        for cycle, component in cycles)


def test_no_private_names_across_modules():
    uses = private_uses()
    assert not uses, "private names used across modules:\n" + "\n".join(uses)


def test_xlfuncs_imports_neither_generator_nor_openpyxl():
    modules = _project_modules()
    bad = []
    for name, path in modules.items():
        if not name.startswith("xlfuncs"):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                tops = [_tree_name(a.name).partition(".")[0] for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module == "cmmwb":
                tops = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                tops = [_tree_name(node.module or "").partition(".")[0]]
            else:
                continue
            bad += [f"{path.relative_to(ROOT)}:{node.lineno}: {t}" for t in tops
                    if t in ("generator", "openpyxl")]
    assert not bad, bad


def _registered_job_modules() -> dict[str, str]:
    """The registry ``JOBS`` of generator/jobs.py, read from the source: kind -> the module its
    entry is bound to (``from .budget import job as budget``)."""
    tree = ast.parse((ROOT / "generator" / "jobs.py").read_text(encoding="utf-8"))
    bound = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            for alias in node.names:
                bound[alias.asname or alias.name] = f"generator.{node.module}.{alias.name}"
    for node in tree.body:
        target = node.target if isinstance(node, ast.AnnAssign) else \
            node.targets[0] if isinstance(node, ast.Assign) else None
        if getattr(target, "id", None) == "JOBS":
            assert isinstance(node.value, ast.Dict), "JOBS is a literal dict"
            return {ast.literal_eval(k): bound[v.id] for k, v in zip(node.value.keys, node.value.values)}
    raise AssertionError("generator/jobs.py has no JOBS")


def test_each_task_kind_has_its_own_package_with_its_job():
    for kind in TASK_KINDS:
        folder = ROOT / "generator" / kind
        assert (folder / "__init__.py").is_file(), folder
    for kind in ("pointcloud", "budget", "feature", "characteristic"):
        assert (ROOT / "generator" / kind / "job.py").is_file(), kind
    assert (ROOT / "generator" / "diagnosis" / "run.py").is_file()
    registered = _registered_job_modules()
    assert registered, "no task kind registered"
    for kind, module in registered.items():
        kind_package = module.split(".")[1]
        assert kind_package == kind and kind in TASK_KINDS and module.endswith(".job"), module
        assert (ROOT / Path(*module.split("."))).with_suffix(".py").is_file(), module


def _cli_sources() -> list[Path]:
    return [ROOT / "generator" / "jobs.py", *sorted((ROOT / "generator" / "cli").glob("*.py"))]


def test_commands_and_kinds_are_static_lists_not_names_imported_at_run_time():
    """No module of the command line or the kind registry imports by string (importlib,
    __import__): every command and every kind is an import the graph above sees."""
    for path in _cli_sources():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [a.name for a in node.names] + [getattr(node, "module", None) or ""]
                assert "importlib" not in names, f"{path.relative_to(ROOT)}:{node.lineno}"
            if isinstance(node, ast.Name):
                assert node.id not in ("__import__", "import_module"), f"{path.relative_to(ROOT)}:{node.lineno}"


def test_every_command_module_is_in_the_static_list():
    """A command module left out of COMMANDS would be a command that silently is not there."""
    tree = ast.parse((ROOT / "generator" / "cli" / "program.py").read_text(encoding="utf-8"))
    listed = next([e.id for e in node.value.elts] for node in tree.body
                  if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", None) == "COMMANDS")
    modules = {p.stem for p in (ROOT / "generator" / "cli").glob("*.py")} - {"__init__", "program", "common"}
    assert sorted(listed) == sorted(modules)


def test_the_command_line_starts_without_the_locator_and_scipy():
    """Every `cmmwb` command builds the whole parser first: the command modules import their
    heavy jobs (the locator, the REML fit, scipy) only when they run, so `cmmwb --help` or
    `cmmwb build` does not pay for them (they had made the start-up 0.5 s against 0.2 s)."""
    import subprocess
    import sys

    code = ("import sys; from cmmwb.generator.cli import program; program.parser(); "
            "heavy = ('scipy', 'cmmwb.xlfuncs.locator.model', 'cmmwb.xlfuncs.locator.diagnose', "
            "'cmmwb.xlfuncs.locator.structured', 'cmmwb.xlfuncs.reml', 'cmmwb.generator.calibration', "
            "'cmmwb.generator.diagnosis'); "
            "print(sorted(m for m in sys.modules if m.startswith(heavy)))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "[]"


#: the GUM modules: decisions, statements, risks, degrees of freedom and the distributions they use
GUM_MODULES = ("xlfuncs.conformity", "xlfuncs.dof", "xlfuncs.statement", "xlfuncs.global_risk",
               "xlfuncs.distributions")


def _reachable(graph: dict[str, set[str]], start: str) -> dict[str, str]:
    """Every module ``start`` imports, directly or through others: module -> the one it came from."""
    seen = {start: ""}
    todo = [start]
    while todo:
        m = todo.pop()
        for t in sorted(graph.get(m, ())):
            if t not in seen:
                seen[t] = m
                todo.append(t)
    return seen


def test_the_gum_modules_do_not_import_the_locator():
    """The JCGM 100/106 modules take their distributions from xlfuncs.distributions, not from the
    mismatch locator (issue 35: dof took Student's t from xlfuncs.locator.stats)."""
    graph = _graph()
    bad = []
    for gum in GUM_MODULES:
        assert gum in graph, gum
        bad += _locator_chains(_reachable(graph, gum))
    assert not bad, bad


def _locator_chains(reach: dict) -> list[str]:
    """Each module of the locator in ``reach`` ({module: the module that imports it}) with the
    chain of imports that reaches it."""
    bad = []
    for m in sorted(reach):
        if m == "xlfuncs.locator" or m.startswith("xlfuncs.locator."):
            chain = [m]
            while reach[chain[-1]]:
                chain.append(reach[chain[-1]])
            bad.append(" <- ".join(chain))
    return bad


def test_build_and_the_core_it_uses_do_not_import_the_locator():
    """`cmmwb build` (every kind: the model records, V_X, budgets, features, characteristics,
    decisions, the workpiece's W) reaches no module of the mismatch locator, directly or through
    others: the locator is for diagnose and calibrate (issue 35)."""
    graph = _graph()
    reach = _reachable(graph, "generator.build")
    core = {m for m in reach if m.startswith("xlfuncs.")}
    assert {"xlfuncs.model.hyperparameters", "xlfuncs.model.workpiece", "xlfuncs.pointcloud", "xlfuncs.budget",
            "xlfuncs.conformity", "xlfuncs.dof", "xlfuncs.distributions"} <= core
    bad = _locator_chains(reach)
    assert not bad, bad


def test_scipy_is_declared_where_the_core_imports_it():
    """A module of xlfuncs or generator that imports scipy needs scipy in [project] dependencies
    (issue 35: five core modules imported it, only the test extra had it)."""
    import tomllib

    deps = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["dependencies"]
    declared = any(d.replace(" ", "").lower().startswith("scipy") for d in deps)
    users = []
    for name, path in _project_modules().items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            mods = ([a.name for a in node.names] if isinstance(node, ast.Import)
                    else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
            if any(m.partition(".")[0] == "scipy" for m in mods):
                users.append(name)
    assert users, "no module imports scipy: drop it from the dependencies"
    assert declared, f"scipy is imported by {sorted(set(users))} but not in [project] dependencies"
