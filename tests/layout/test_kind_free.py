"""The code every task kind shares names no task kind (issue 32): decisions, the Decision sheet,
the report page, the cached values and the way back take what they need of a kind's results from
its records (`generator.quantities`, `TaskKind.quantities`) and its `TOLERANCE_KEYS`. A new kind is
its package plus its line in `generator.jobs.JOBS` and `generator.taskfile.KINDS`.

Read from the source text with `ast` (nothing is imported): a shared module names a kind when a
string constant in it is a kind's name (or the name of a book that is no task: `diagnose`,
`calibrate`). The one kind name that is also a word of the external contract, `characteristic`
(the JSON key of a decision, a column header), is flagged only where it is compared, collected in a
tuple or set, or keyed beside another kind's name, i.e. where it selects a kind.
"""

from __future__ import annotations

import ast
from pathlib import Path

from cmmwb.generator.taskfile import KINDS

ROOT = Path(__file__).resolve().parents[2]
#: the shared modules: generator/*.py, generator/workbook/, generator/decision/
SHARED = sorted([*(ROOT / "generator").glob("*.py"), *(ROOT / "generator" / "workbook").rglob("*.py"),
                 *(ROOT / "generator" / "decision").rglob("*.py")])
#: the two places a kind is registered (the kinds' list itself), and the one that describes the
#: folders `cmmwb demo` writes, which are named after the kinds (the demo index's headings: a
#: description of those folders, not a choice between kinds; a kind without one is listed under
#: its folder's name)
REGISTRY = {"generator/jobs.py": None, "generator/taskfile.py": "KINDS", "generator/demo_index.py": "GROUPS"}
#: names of books that are not task kinds but were once selected by name in shared code
OTHER_BOOKS = ("diagnose", "calibrate", "diagnosis", "calibration")
WORD = "characteristic"


def _parents(tree: ast.AST) -> dict[ast.AST, ast.AST]:
    return {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}


def _selects(node: ast.Constant, parents: dict) -> bool:
    """Whether the word ``characteristic`` is used to select a kind here."""
    parent = parents.get(node)
    if isinstance(parent, ast.Compare):
        return True
    if isinstance(parent, (ast.Tuple, ast.Set)):
        return True
    if isinstance(parent, ast.Dict) and node in parent.keys:
        return sum(isinstance(k, ast.Constant) and k.value in KINDS for k in parent.keys) > 1
    return False


def kind_names(path: Path) -> list[str]:
    """``file:line: 'name'`` for every place ``path`` names a task kind."""
    rel = path.relative_to(ROOT).as_posix()
    if rel in REGISTRY and REGISTRY[rel] is None:
        return []
    tree = ast.parse(path.read_text(encoding="utf-8"))
    parents = _parents(tree)
    allowed: set[ast.AST] = set()
    if REGISTRY.get(rel):
        for node in ast.walk(tree):
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == REGISTRY[rel]
                                                    for t in node.targets):
                allowed |= set(ast.walk(node.value))
    out = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Constant) and isinstance(node.value, str)) or node in allowed:
            continue
        if isinstance(parents.get(node), ast.Expr):       # a docstring
            continue
        v = node.value
        if (v in KINDS and v != WORD) or v in OTHER_BOOKS or (v == WORD and _selects(node, parents)):
            out.append(f"{rel}:{node.lineno}: {v!r}")
    return out


def test_the_shared_modules_name_no_task_kind():
    found = [hit for path in SHARED for hit in kind_names(path)]
    assert not found, "shared code selects a task kind by its name:\n" + "\n".join(found)


def test_the_check_finds_a_kind_selected_by_name(tmp_path):
    """The check itself: the constructs the shared code used before the records."""
    src = tmp_path / "generator" / "shared.py"
    src.parent.mkdir()
    src.write_text('K_KINDS = ("feature", "characteristic")\n'
                   'IDENT_KEYS = {"budget": ("characteristic",), "characteristic": ("characteristic",)}\n'
                   'def f(kind, results):\n'
                   '    if kind == "pointcloud":\n'
                   '        return results["feature"]\n'
                   '    if kind in ("diagnose", "calibrate"):\n'
                   '        return {"characteristic": 1}\n', encoding="utf-8")
    global ROOT
    old, ROOT = ROOT, tmp_path
    try:
        hits = kind_names(src)
    finally:
        ROOT = old
    names = [h.split(": ", 1)[1] for h in hits]
    assert names.count("'characteristic'") == 4        # in tuples, and as a key beside 'budget'
    assert {"'feature'", "'budget'", "'pointcloud'", "'diagnose'", "'calibrate'"} <= set(names)
    assert "generator/shared.py:7: 'characteristic'" not in hits    # the JSON key of a decision


def test_every_kind_is_its_package_and_its_line_in_the_registry():
    from cmmwb.generator.jobs import JOBS

    assert tuple(JOBS) == KINDS
    for kind in KINDS:
        assert (ROOT / "generator" / kind / "job.py").is_file(), kind
