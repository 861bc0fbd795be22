"""docs/developing.md matches the tree (issue 27): what it names exists, and every module of
`generator/` and `xlfuncs/` has its place in its table.

Read from the text only (nothing is imported): a path in backticks that begins with a folder of
the tree must exist; a dotted name in backticks that begins with ``generator.``, ``xlfuncs.`` or
``cmmwb.`` must be a module of the tree, optionally followed by a name that module defines (and, for
a class, an attribute of its body); a file name in backticks (``read.py``) must be the name of a
file of the tree.  The same checks run over the other documents of the repository (README.md,
docs/*.md, the READMEs of workbook_templates/ and tests/data/), so that a module moved without its
documentation fails here, not in a reader's hands.

The table ``| where | job | may import |`` of docs/developing.md: every module of generator/ and
xlfuncs/ (but ``__init__.py``, ``__main__.py`` and the add-in files of generator/lo_addin/) has
exactly one row, either by its full path in the row's first cell or, for a module of a package,
by the package's folder in the first cell and the module's name (``program.py`` or ``program``)
in the row; every package has a row (or a row of one of its modules); every path of a first
cell exists.
"""

from __future__ import annotations

import ast
import re
import subprocess
from functools import cache
from pathlib import Path

from tests.helpers import ROOT

DEVELOPING = ROOT / "docs" / "developing.md"

#: the folders a repository path in a document begins with
TOP = ("generator", "xlfuncs", "tests", "bench", "docs", "workbook_templates", ".github")
#: the documents whose backticked paths and module names must exist (developing.md among them)
DOCUMENTS = ("README.md", "docs/*.md", "workbook_templates/README.md", "tests/data/**/README*")
#: file names a document names on purpose although the tree has no such file: a user's own
#: ``generator.py`` or ``cmmwb.py`` beside a workbook (docs/developing.md, "Packaging")
NOT_IN_THE_TREE = {"generator.py", "xlfuncs.py", "cmmwb.py"}

_CODE = re.compile(r"`([^`\n]+)`")
_PATH = re.compile(r"^\.?[A-Za-z_][\w.-]*/[\w./*-]*$")
_DOTTED = re.compile(r"^(?:cmmwb\.)?(?:generator|xlfuncs)(?:\.\w+)+(?::\w+)?$")
_FILE = re.compile(r"^\w[\w-]*\.py$")


@cache
def tracked() -> frozenset[str]:
    """The files of the tree, as paths relative to the repository: ``git ls-files`` and the Python
    files on disk (a new module counts before ``git add``; build outputs and caches do not)."""
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    on_disk = {p.relative_to(ROOT).as_posix() for top in ("generator", "xlfuncs", "tests", "bench")
               for p in (ROOT / top).rglob("*.py") if "__pycache__" not in p.parts}
    return frozenset(out.splitlines()) | on_disk


def path_exists(path: str) -> bool:
    """A file or folder of the tree (``generator/cli/``, ``tests/helpers/clouds.py``); a glob
    (``tests/data/**/README*``) must match at least one file."""
    path = path.rstrip("/")
    if any(c in path for c in "*?["):
        return any(p.relative_to(ROOT).as_posix() in tracked() for p in ROOT.glob(path))
    return path in tracked() or any(f.startswith(path + "/") for f in tracked())


def module_file(dotted: str) -> Path | None:
    """The file of the module ``generator.x.y`` (or ``cmmwb.generator.x.y``), or None."""
    parts = dotted.removeprefix("cmmwb.").split(".")
    base = ROOT.joinpath(*parts)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.relative_to(ROOT).as_posix() in tracked():
            return candidate
    return None


def _defined(body: list[ast.stmt]) -> dict[str, ast.AST]:
    """Names a module or class body binds: definitions, assignments, imports (also inside
    if/try/with at that level)."""
    out: dict[str, ast.AST] = {}
    for node in body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out[node.name] = node
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                for name in ast.walk(target):
                    if isinstance(name, ast.Name):
                        out[name.id] = node
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            for alias in node.names:
                out[(alias.asname or alias.name).partition(".")[0]] = node
        elif isinstance(node, (ast.If, ast.Try, ast.With)):
            for block in ("body", "orelse", "finalbody", "handlers"):
                for sub in getattr(node, block, []):
                    out.update(_defined(sub.body if isinstance(sub, ast.ExceptHandler) else [sub]))
    return out


@cache
def _module_names(path: Path) -> dict[str, ast.AST]:
    return _defined(ast.parse(path.read_text(encoding="utf-8")).body)


def dotted_exists(name: str) -> bool:
    """``generator.cli:main``, ``xlfuncs.errors.ModelError``, ``generator.workbook.book.Book.save``:
    the longest prefix that is a module of the tree, then a name it defines, then (for a class)
    an attribute its body defines."""
    parts = name.replace(":", ".").split(".")
    for cut in range(len(parts), 0, -1):
        path = module_file(".".join(parts[:cut]))
        if path is None:
            continue
        rest = parts[cut:]
        if not rest:
            return True
        node = _module_names(path).get(rest[0])
        if node is None:
            return False
        if len(rest) > 1 and isinstance(node, ast.ClassDef):
            return rest[1] in _defined(node.body) or any(
                isinstance(n, ast.FunctionDef) and n.name == "__init__" and any(
                    isinstance(t, ast.Attribute) and t.attr == rest[1] for t in ast.walk(n))
                for n in node.body)
        return True
    return False


def stale_names(text: str) -> list[str]:
    """The backticked repository paths, module names and file names of a document that do not
    exist in the tree."""
    out = []
    for token in _CODE.findall(text):
        token = token.strip()
        head = token.split("/", 1)[0]
        if _FILE.match(token):
            if token not in NOT_IN_THE_TREE and not any(f == token or f.endswith("/" + token) for f in tracked()):
                out.append(token)
        elif _PATH.match(token) and head in TOP:
            if not path_exists(token):
                out.append(token)
        elif _DOTTED.match(token):
            if not dotted_exists(token):
                out.append(token)
    return out


def documents() -> list[Path]:
    found = {p for pattern in DOCUMENTS for p in ROOT.glob(pattern)
             if p.is_file() and p.relative_to(ROOT).as_posix() in tracked()}
    return sorted(found)


# --- the layout table of docs/developing.md -----------------------------------------------------

def layout_rows(text: str) -> list[tuple[list[str], str]]:
    """The rows of the table ``| where | job | may import |``: (the paths of its first cell, the
    whole row)."""
    rows, inside = [], False
    for line in text.splitlines():
        if line.startswith("| where | job | may import |"):
            inside = True
            continue
        if inside and not line.startswith("|"):
            break
        if inside and not line.startswith("|---"):
            cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
            rows.append((_CODE.findall(cells[0]), line))
    return rows


def project_modules() -> list[str]:
    """Every Python file of generator/ and xlfuncs/ a table row must account for, and every
    package as ``folder/``: without ``__init__.py`` and ``__main__.py`` (their package's row covers
    them) and without the LibreOffice add-in's files (``generator/lo_addin/``, package data run by
    LibreOffice, one row)."""
    out = set()
    for f in tracked():
        if not f.startswith(("generator/", "xlfuncs/")) or f.startswith("generator/lo_addin/"):
            continue
        path = Path(f)
        if path.name == "__init__.py":
            if len(path.parts) > 2:         # generator/ and xlfuncs/ themselves: the whole table
                out.add(path.parent.as_posix() + "/")
        elif path.suffix == ".py" and path.name != "__main__.py":
            out.add(f)
    return sorted(out)


def covered(module: str, rows: list[tuple[list[str], str]]) -> bool:
    """A row names the module: its full path in the first cell, or the first cell names its
    package (``generator/cli/``) and the row names the module (``program.py`` or ``program``)."""
    if module.endswith("/"):                # a package: its row, or a row of one of its modules
        return any(p.startswith(module) for paths, _row in rows for p in paths)
    folder, _, name = module.rpartition("/")
    stem = name.removesuffix(".py")
    for paths, row in rows:
        if module in paths:
            return True
        if folder + "/" in paths:
            named = set(_CODE.findall(row))
            if name in named or stem in named:
                return True
    return False


def test_every_module_and_package_has_its_row():
    rows = layout_rows(DEVELOPING.read_text(encoding="utf-8"))
    assert len(rows) > 20, "the table | where | job | may import | was not found"
    missing = [m for m in project_modules() if not covered(m, rows)]
    assert not missing, "modules without a row in docs/developing.md:\n" + "\n".join(missing)


def test_every_row_names_what_exists():
    rows = layout_rows(DEVELOPING.read_text(encoding="utf-8"))
    stale = [p for paths, _row in rows for p in paths if not path_exists(p)]
    assert not stale, stale


def test_no_module_has_two_rows():
    rows = layout_rows(DEVELOPING.read_text(encoding="utf-8"))
    seen: dict[str, str] = {}
    twice = []
    for paths, row in rows:
        for module in project_modules():
            if not module.endswith("/") and covered(module, [(paths, row)]):
                if module in seen and seen[module] != row:
                    twice.append(module)
                seen[module] = row
    assert not twice, "modules with two rows in docs/developing.md (merge them):\n" + "\n".join(sorted(set(twice)))


def test_developing_names_only_what_exists():
    stale = stale_names(DEVELOPING.read_text(encoding="utf-8"))
    assert not stale, "docs/developing.md names what the tree does not have:\n" + "\n".join(stale)


def test_the_documents_name_only_what_exists():
    stale = [f"{doc.relative_to(ROOT)}: {name}" for doc in documents()
             for name in stale_names(doc.read_text(encoding="utf-8"))]
    assert not stale, "documents name what the tree does not have:\n" + "\n".join(stale)


def test_the_checks_find_a_stale_name():
    """The checks above can fail: names of the tree before issue 27 are reported."""
    assert stale_names("`generator/cli.py`, `xlfuncs/diagnose.py`, `read_cli.py`, `generator.jobs.JOB_MODULES`, "
                       "`xlfuncs.effects`, `tests/test_layout.py`") == [
        "generator/cli.py", "xlfuncs/diagnose.py", "read_cli.py", "generator.jobs.JOB_MODULES",
        "xlfuncs.effects", "tests/test_layout.py"]
    assert stale_names("`generator/cli/`, `xlfuncs/locator/diagnose.py`, `program.py`, `generator.jobs.JOBS`, "
                       "`cmmwb.xlfuncs.udf`, `generator.cli:main`, `generator.workbook.book.Book.save`") == []
