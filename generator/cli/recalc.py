"""``cmmwb recalc BOOK.xlsx``: a workbook recomputed headlessly (Gnumeric, LibreOffice or
``formulas``; by default the fastest installed), its Results sheet printed as a table or JSON."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..errors import InputError
from ..workbook.recalc import ENGINES, default_engine, installed
from .common import add_command


def register(sub) -> None:
    s = add_command(sub, "recalc", "recompute a workbook headlessly and print its Results",
                    "Recomputes every formula of a workbook with the chosen engine (a forced full "
                    "recalculation) and prints the Results sheet as a table or JSON.",
                    ("cmmwb recalc gauge/my_pointcloud.xlsx",
                     "cmmwb recalc gauge/my_pointcloud.xlsx --engine libreoffice --json"))
    s.add_argument("book", metavar="BOOK.xlsx", help="the workbook (written by cmmwb build, possibly edited)")
    s.add_argument("--engine", choices=ENGINES, default=None,
                   help="gnumeric: Gnumeric's ssconvert, headless; libreoffice: a real headless LibreOffice "
                        "(soffice); formulas: the pure-Python engine, in process (slow on large books: "
                        "24-34 s where Gnumeric takes under 1 s). Default: the fastest installed, in that "
                        "order (said on stderr)")
    s.add_argument("--json", action="store_true", help="print the Results rows as JSON (default: a table)")
    s.set_defaults(func=run)


def run(args) -> int:
    from ..workbook.recalc import RecalcError, recalculate, recalculate_checking_cycles, results_rows
    from ..workbook.safe_xlsx import MAX_CELLS, MAX_FORMULAS_ENGINE_CELLS, check

    path = Path(args.book)
    if not path.exists():
        raise InputError("no such file", file=path)
    engine = args.engine or default_engine()
    if args.engine and not installed(engine):
        raise InputError(f"the {engine} engine is not installed here; installed: "
                         f"{', '.join(e for e in ENGINES if installed(e))}", file=path)
    # an untrusted file, checked before any engine sees it: regular file, size, zip bomb,
    # entities in any part, macros, external links, DDE, queries, cell and string counts
    check(path, max_cells=MAX_FORMULAS_ENGINE_CELLS if engine == "formulas" else MAX_CELLS)
    if args.engine is None:   # said only once the file is accepted: a refusal stays one line
        print(f"cmmwb recalc: engine {engine} (the fastest installed; --engine to choose another)",
              file=sys.stderr)
    try:
        if engine == "gnumeric":   # Gnumeric iterates a cycle without an error value: checked
            values, cycle = recalculate_checking_cycles(path)
        else:
            values, cycle = recalculate(path, engine), []
    except RecalcError as e:
        raise InputError(str(e), file=path) from None
    if cycle:
        raise InputError(f"a circular reference: {len(cycle)} formula cell(s) depend on themselves or on a cell "
                         f"that does, e.g. {cycle[0]}; cmmwb's workbooks have none (was a formula edited?)",
                         file=path)
    if "Results" not in values:
        raise InputError("no sheet named 'Results'", file=path, where="sheet Results")
    rows = results_rows(values)
    errors = [(k, v) for r in rows for k, v in r.items() if isinstance(v, str) and v.startswith("#")]
    if errors and engine != "formulas":
        _refuse_circular_references(path)   # LibreOffice and Gnumeric show a cycle only as an error value
    if args.json:
        print(json.dumps(rows, indent=1, ensure_ascii=False, default=str))
        return 0
    if rows:
        keys = list(rows[0])
        print("\t".join(keys))
        for r in rows:
            print("\t".join(f"{v + 0.0:.6g}" if isinstance(v, float) else "" if v is None else str(v)
                            for v in r.values()))   # + 0.0: a -0 prints as 0
    if errors:
        print(f"cmmwb: {len(errors)} Results cells evaluate to errors, e.g. {errors[0][0]} = {errors[0][1]}",
              file=sys.stderr)
        return 1
    return 0


def _refuse_circular_references(path: Path) -> None:
    """A circular reference is a clear error (exit 2); looked for with the ``formulas`` engine
    when LibreOffice gave error values and the workbook is small enough for that engine."""
    from ..workbook.recalc import RecalcError, check_no_cycles
    from ..workbook.safe_xlsx import MAX_FORMULAS_ENGINE_CELLS, check

    try:
        check(path, max_cells=MAX_FORMULAS_ENGINE_CELLS)
    except InputError:
        return
    try:
        check_no_cycles(path)
    except RecalcError as e:
        raise InputError(str(e), file=path) from None
    except Exception:  # the other engine cannot read it: the error values speak for themselves
        return
