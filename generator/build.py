"""Building a task: load, compute, write the workbook, JSON and plots into a folder, all or
nothing, never over a file someone edited (unless forced, with a backup)."""

from __future__ import annotations

import csv
import json
import math
import sys
import warnings
from pathlib import Path

from openpyxl.utils.exceptions import IllegalCharacterError

from . import decision as decisions
from . import report
from .errors import InputError, model_errors_named
from .jobs import job
from .taskfile import collecting_notes, naming_lines, read_toml, task_kind_and_name
from .workbook.atomic import Staging
from .workbook.book import BookAdditions
from .workbook.provenance import provenance


def non_finite(obj, where: str = "results"):
    """The first NaN or infinity in the results (JSON path, value), or None."""
    if isinstance(obj, float):
        return None if math.isfinite(obj) else (where, obj)
    items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, list) else ()
    for k, v in items:
        hit = non_finite(v, f"{where}.{k}" if isinstance(k, str) else f"{where}[{k}]")
        if hit is not None:
            return hit
    return None


def load_task(task_path: Path):
    """Read and validate a task file and its tables: (kind, job module, TOML document, task).
    Every problem is an :class:`InputError` (exit status 2)."""
    task_path = Path(task_path)
    doc = read_toml(task_path)
    with naming_lines(task_path):
        kind, _ = task_kind_and_name(task_path, doc)
    mod = job(kind)
    try:
        with model_errors_named(task_path), warnings.catch_warnings(), naming_lines(task_path):
            warnings.simplefilter("ignore", RuntimeWarning)
            task = mod.load(task_path, doc)
    except csv.Error as e:  # a malformed points table that the CSV module itself rejects
        raise InputError(f"malformed points table ({e})", file=task_path, where="[points]") from None
    return kind, mod, doc, task


def sheet_writers(spec, quantities: list, verdicts: list, results: dict, keys) -> list:
    """The sheets every book of the task gets besides its kind's: ``Decision`` (when the task has
    decisions) and ``Summary``, the report page (:mod:`generator.report`), both from the task's
    records; the values they cache are given with their formulas."""
    rows: dict[str, int] = {}
    decided = spec is not None and bool(spec.tolerances)

    def decision_sheet(book):
        rows.update(decisions.write_sheet(book, spec, quantities, results["decisions"]))

    def summary_sheet(book):
        report.write_sheet(book, results, quantities, verdicts, keys=keys, decision_rows=rows or None,
                           k_cell="decision_k" if decided and spec.k is not None else None)

    return ([decision_sheet] if decided else []) + [summary_sheet]


def build_task(task_path: Path, out_dir: Path, *, plots: bool = True, force: bool = False,
               cache: str = "results", exact: bool = False, pdf: bool = False,
               built_utc: str | None = None) -> tuple[dict, list[Path]]:
    """Build one task into ``out_dir``: workbook, JSON and plots, all or nothing.

    ``force``: replace outputs someone edited (keeping backups); ``cache``: which formula cells
    get cached values for programs that do not calculate (see :mod:`generator.workbook.cache`;
    the writers give the values with their formulas);
    ``exact``: no approximation even for large tasks (the job's ``force_exact``: a feature task's
    V_A; the other kinds are always exact); ``pdf``: the workbook printed to PDF by
    LibreOffice, inside the same all-or-nothing commit (so the manifest lists it, and a later build
    without ``pdf`` removes it); ``built_utc``: the build time to record (default: now)."""
    task_path = Path(task_path)
    with collecting_notes() as notes:
        kind, mod, doc, task = load_task(task_path)
        keys = mod.TOLERANCE_KEYS
        spec = decisions.read_spec(task_path, doc, keys)
        rep = report.read_report(task_path, doc)
    if exact:
        mod.force_exact(task)
    with model_errors_named(task_path), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # numpy's; a non-finite result is caught below
        results = mod.compute(task)
        quantities = mod.quantities(task, results, spec.k if spec is not None and spec.k is not None else 2.0)
        verdicts = mod.verdicts(task, results)
    if spec is None:
        spec = decisions.default_spec(keys, quantities)     # a drawing's own tolerances, the default rule
    if spec is not None:
        results["decision_rule"] = decisions.rule_json(spec)
        results["decisions"], skipped = decisions.decide_all(task_path, keys, spec, quantities)
        if skipped:
            results["not_decided"] = skipped
        mod.add_type_a(results)                 # a kind's budgets show the type A inputs (budget)
    results["statements"] = report.statements(quantities, results.get("decisions", []))
    results["provenance"] = provenance(task_path, doc, built_utc)
    if rep is not None:
        results["report"] = rep

    results["warnings"] = list(notes)     # docs/cli.md: what was detected or looks implausible
    bad = non_finite(results)
    if bad is not None:
        raise InputError(f"the model gives {bad[1]!r} for {bad[0]}: check the inputs for extreme values "
                         "(e.g. a length scale so small that its square underflows)", file=task_path)
    staging = Staging(out_dir, force=force, task=results["name"])
    with staging as tmp:
        name = results["name"]
        book = tmp / f"{name}.xlsx"
        try:
            mod.write_book(task, results, book, BookAdditions(
                info={"kind": kind, "name": name, "doc": doc, "task_file": task_path.name},
                sheets=tuple(sheet_writers(spec, quantities, verdicts, results, keys)), cache=cache))
        except IllegalCharacterError:
            raise InputError("a text (a point, probe or characteristic name, or a note) contains a control "
                             "character that a workbook cannot store", file=task_path) from None
        (tmp / f"{name}.json").write_text(json.dumps(results, indent=1, ensure_ascii=False) + "\n",
                                          encoding="utf-8")
        made = [tmp / f"{name}.xlsx", tmp / f"{name}.json"]
        if plots:
            made += list(mod.write_plots(task, results, tmp))
        if pdf:
            from .workbook.pdf import print_books

            made += print_books([tmp / f"{name}.xlsx"])
    for w in notes:
        print(f"cmmwb: warning: {w}", file=sys.stderr)
    for b in staging.backups:
        print(f"cmmwb: kept a backup of the replaced file: {b}", file=sys.stderr)
    for r in staging.removed:
        print(f"cmmwb: removed {r}: written by this task's previous build, not by this one", file=sys.stderr)
    return results, [Path(out_dir) / p.name for p in made]
