"""Where an influence factor is named in the code: the measure of issue 35 ("adding a factor changes
one hyper-parameter table, not seven").

For a factor (``ER`` by default) a *mention* is a line of Python code under ``xlfuncs/`` or
``generator/`` that names it: a string constant equal to the factor's label (``"ER"``) or containing
one of its hyper-parameter names as a word (``"sigma_ER_urad"``, an f-string's text), or an
identifier, attribute or keyword argument spelled like one of them (``params.sigma_ER_urad``).
Docstrings and comments are not code and are not counted. Each mention is put in one of three
places:

* ``record``: the factor's own record, ``xlfuncs/model/hyperparameters.py``;
* ``writers``: the workbook writers, modules that import ``generator.workbook.book`` (they write the
  factor's live formulas, which name its cells);
* ``elsewhere``: everything else -- the places a new factor would have to be typed into by hand.

Usage (from the repository's root): ``python bench/factor_mentions.py [FACTOR ...]``; prints one
table per factor (files and lines per place, and the files ``elsewhere``).  The numbers quoted in
``docs/developing.md`` ("One record per hyper-parameter") come from this script.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORD = "xlfuncs/model/hyperparameters.py"

#: the hyper-parameter names of each factor (task-file keys), and of the factor W the workpiece's
NAMES = {
    "R": ("sigma_R_um",),
    "PQ": ("sigma_PQ_um",),
    "S": ("sigma_S_ppm", "sigma_Sa_ppm", "sigma_Q_ppm"),
    "ET": ("sigma_ET_um", "lambda_ET_mm"),
    "ER": ("sigma_ER_urad", "lambda_ER_mm"),
    "P": ("sigma_P0_um", "sigma_P_um", "lambda_P"),
    "W": ("u_alpha_ppm_per_K", "u_T_K"),
}


def _docstrings(tree: ast.AST) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = getattr(node, "body", [])
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                ids.add(id(body[0].value))
    return ids


def _is_writer(tree: ast.AST, rel: str) -> bool:
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and \
                (node.module.endswith("workbook.book") or (node.module.endswith("workbook")
                                                            and any(a.name == "book" for a in node.names))
                 or (node.module == "book" and node.level == 1 and rel.startswith("generator/workbook/"))):
            return True
    return False


def mentions(factor: str, root: Path = ROOT) -> dict[str, dict[str, set[int]]]:
    """{place: {file: lines}} of the factor's mentions in the code (see the module's docstring)."""
    names = NAMES[factor]
    word = re.compile(r"\b(" + "|".join(map(re.escape, names)) + r")\b")
    out: dict[str, dict[str, set[int]]] = {"record": {}, "writers": {}, "elsewhere": {}}
    for path in sorted([*root.glob("xlfuncs/**/*.py"), *root.glob("generator/**/*.py")]):
        rel = path.relative_to(root).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = _docstrings(tree)
        lines: set[int] = set()
        for node in ast.walk(tree):
            hit = False
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip:
                hit = node.value == factor or bool(word.search(node.value))
            elif isinstance(node, ast.Name):
                hit = node.id in names
            elif isinstance(node, ast.Attribute):
                hit = node.attr in names
            elif isinstance(node, ast.keyword):
                hit = node.arg in names
            if hit and hasattr(node, "lineno"):
                lines.add(node.lineno)
        if not lines:
            continue
        place = "record" if rel == RECORD else "writers" if _is_writer(tree, rel) else "elsewhere"
        out[place][rel] = lines
    return out


def report(factor: str) -> str:
    m = mentions(factor)
    rows = [f"factor {factor} ({', '.join(NAMES[factor])})", "",
            "| place | files | lines |", "|---|---|---|"]
    for place in ("record", "writers", "elsewhere"):
        files = m[place]
        rows.append(f"| {place} | {len(files)} | {sum(len(v) for v in files.values())} |")
    rows.append("")
    rows.append("elsewhere: " + (", ".join(f"{f} ({len(v)})" for f, v in m["elsewhere"].items()) or "none"))
    return "\n".join(rows)


if __name__ == "__main__":
    for f in sys.argv[1:] or ["ER"]:
        print(report(f))
        print()
