"""The ``cmmwb`` command line (thin: parsing, output folders, error reporting).

Exit status: 0 success, 2 bad input (one message naming the file and line/key/sheet/cell),
1 an internal error (a bug: please report it with the task file).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from xlfuncs.errors import ModelError

from . import __version__
from .atomic import write_text
from .build import build_task
from .errors import InputError
from .jobs import available, job
from .taskfile import KINDS

EXAMPLES_DIR = Path(__file__).parent / "examples"


# -- commands ----------------------------------------------------------------------------------

def cmd_build(args) -> int:
    results, files = build_task(Path(args.task), Path(args.out), plots=not args.no_plots,
                                force=args.force, cache=args.cache)
    for f in files:
        print(f)
    return 0


def cmd_new(args) -> int:
    if args.kind not in available():
        raise InputError(f"task kind {args.kind!r} is not available in this installation")
    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError("exists already (use --force to overwrite)", file=out)
    write_text(out, job(args.kind).NEW_TASK)
    print(out)
    for fname, content in getattr(job(args.kind), "NEW_TASK_FILES", {}).items():
        extra = out.parent / fname
        if extra.exists():
            print(f"{extra} exists already: kept as it is")
            continue
        write_text(extra, content)
        print(extra)
    return 0


def cmd_demo(args) -> int:
    out = Path(args.out)
    t0 = time.perf_counter()
    print(f"cmmwb {__version__} demo: building the worked examples of the three papers into {out}/")
    for kind in available():
        mod = job(kind)
        for example in mod.EXAMPLES:
            t = time.perf_counter()
            results, files = build_task(EXAMPLES_DIR / example, out / kind)
            print(f"\n[{kind}] {results['name']}  ({time.perf_counter() - t:.1f} s)")
            for line in mod.summary(results):
                print(f"    {line}")
            for f in files:
                print(f"    -> {f}")
    try:
        from . import diagnose_cli
    except ModuleNotFoundError:
        diagnose_cli = None
    if diagnose_cli is not None:
        diagnose_cli.demo(out / "diagnose")
    print(f"\nDone in {time.perf_counter() - t0:.1f} s. Open the .xlsx files in Excel or LibreOffice; "
          "every number is a formula you can follow back to the inputs.")
    return 0


def cmd_recalc(args) -> int:
    from .recalc import RecalcError, recalculate, results_rows

    from .safe_xlsx import check

    path = Path(args.book)
    if not path.exists():
        raise InputError("no such file", file=path)
    check(path)  # an untrusted file: size, zip bomb, entities, macros
    try:
        values = recalculate(path, args.engine)
    except RecalcError as e:
        raise InputError(str(e), file=path) from None
    if "Results" not in values:
        raise InputError("no sheet named 'Results'", file=path, where="sheet Results")
    rows = results_rows(values)
    if args.json:
        print(json.dumps(rows, indent=1, ensure_ascii=False, default=str))
        return 0
    if rows:
        keys = list(rows[0])
        print("\t".join(keys))
        for r in rows:
            print("\t".join(f"{v:.6g}" if isinstance(v, float) else "" if v is None else str(v)
                            for v in r.values()))
    errors = [(k, v) for r in rows for k, v in r.items() if isinstance(v, str) and v.startswith("#")]
    if errors:
        print(f"cmmwb: {len(errors)} Results cells evaluate to errors, e.g. {errors[0][0]} = {errors[0][1]}",
              file=sys.stderr)
        return 1
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cmmwb", description=(
        "Task-specific uncertainty of CMM measurements as live spreadsheet workbooks "
        "(Forbes 2025, Wojtyla/Plowucha 2023, Forbes 2022)."))
    p.add_argument("--version", action="version", version=f"cmmwb {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("demo", help="build every worked example of the three papers")
    s.add_argument("--out", default="cmmwb-demo", help="output folder (default: cmmwb-demo)")
    s.set_defaults(func=cmd_demo)

    s = sub.add_parser("new", help="write a commented task file to start from")
    s.add_argument("kind", choices=KINDS)
    s.add_argument("--out", required=True, help="task file to write")
    s.add_argument("--force", action="store_true", help="overwrite an existing file")
    s.set_defaults(func=cmd_new)

    s = sub.add_parser("build", help="task file -> workbook + JSON (+ plots)")
    s.add_argument("task")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    s.add_argument("--force", action="store_true",
                   help="replace outputs that were edited since cmmwb wrote them (keeps NAME.bak backups)")
    s.add_argument("--cache", choices=("results", "all", "none"), default="results",
                   help="cached values for programs that do not calculate: the Results sheet from the "
                        "JSON (default), every formula cell as the `formulas` engine computes it (slow "
                        "for big workbooks), or none")
    s.set_defaults(func=cmd_build)

    s = sub.add_parser("recalc", help="recompute a workbook headlessly and print its Results")
    s.add_argument("book")
    s.add_argument("--engine", choices=("formulas", "libreoffice"), default="formulas")
    s.add_argument("--json", action="store_true", help="print the Results rows as JSON")
    s.set_defaults(func=cmd_recalc)

    for extra in ("read_cli", "diagnose_cli", "addin_cli", "import_cli"):
        try:
            mod = __import__(f"generator.{extra}", fromlist=["register"])
        except ModuleNotFoundError:
            continue
        mod.register(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return args.func(args)
    except InputError as e:
        print(f"cmmwb: error: {e}", file=sys.stderr)
        return 2
    except ModelError as e:
        print(f"cmmwb: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cmmwb: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # a bug: say so plainly
        if os.environ.get("CMMWB_DEBUG"):
            raise
        print(f"cmmwb: internal error ({type(e).__name__}: {e}); rerun with CMMWB_DEBUG=1 for a "
              "traceback and please report it", file=sys.stderr)
        return 1
