"""The ``cmmwb`` command line (thin: parsing, output folders, error reporting).

The subcommands of :data:`EXTRA_COMMANDS` register themselves with
:func:`generator.commands.add_command`; they never import this module.

Exit status: 0 success, 2 bad input (one message naming the file and line/key/sheet/cell),
1 an internal error (a bug: please report it with the task file).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import textwrap
import time
from pathlib import Path

from xlfuncs.errors import ModelError

from . import __version__
from .build import build_task
from .commands import add_command, examples_epilog
from .errors import InputError, os_error_reason
from .jobs import available, job
from .report import summary_lines
from .taskfile import KINDS
from .workbook.atomic import write_text

EXAMPLES_DIR = Path(__file__).parent / "examples"
#: modules that add their subcommands (``register(sub)``), when present in this installation
EXTRA_COMMANDS = ("generator.read_cli", "generator.diagnosis.cli", "generator.addin_cli",
                  "generator.import_cli",
                  "generator.calibration.cli")


# -- commands ----------------------------------------------------------------------------------

def cmd_build(args) -> int:
    if args.pdf:
        from .workbook.pdf import require_libreoffice

        require_libreoffice()   # before anything is written
    results, files = build_task(Path(args.task), Path(args.out), plots=not args.no_plots,
                                force=args.force, cache=args.cache, exact=args.exact, pdf=args.pdf)
    print(f"[{results['kind']}] {results['name']}")
    for line in job(results["kind"]).summary(results) + summary_lines(results):
        print(f"    {line}")
    for f in files:
        print(f"    -> {f}")
    return 0


def cmd_new(args) -> int:
    if args.kind not in available():
        raise InputError(f"task kind {args.kind!r} is not available in this installation")
    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError("exists already (use --force to overwrite)", file=out)
    text, extras = new_task(args.kind, out.stem)
    for fname, content in extras.items():
        extra = out.parent / fname
        if extra.exists():
            print(f"{extra} exists already: kept as it is")
            continue
        write_text(extra, content)
        print(extra)
    write_text(out, text)  # after its points table: a task never names a file that is not there
    print(out)
    return 0


def new_task(kind: str, stem: str) -> tuple[str, dict[str, str]]:
    """The starter task of ``kind`` for a task file named ``stem``.toml, and the files it needs
    beside it, named after the task (``points.csv`` -> ``<stem>_points.csv``)."""
    mod = job(kind)
    text, extras = mod.NEW_TASK, {}
    for fname, content in getattr(mod, "NEW_TASK_FILES", {}).items():
        mine = f"{stem}_{fname}"
        text = text.replace(f'file = "{fname}"', f'file = "{mine}"')
        extras[mine] = content
    return text, extras


def cmd_demo(args) -> int:
    out = Path(args.out)
    if getattr(args, "pdf", False):
        from .workbook.pdf import require_libreoffice

        require_libreoffice()
    t0 = time.perf_counter()
    print(f"cmmwb {__version__} demo: building the worked examples of the three papers into {out}/")
    for kind in available():
        mod = job(kind)
        for example in mod.EXAMPLES:
            t = time.perf_counter()
            results, files = build_task(EXAMPLES_DIR / example, out / kind, pdf=getattr(args, "pdf", False))
            print(f"\n[{kind}] {results['name']}  ({time.perf_counter() - t:.1f} s)")
            for line in mod.summary(results) + summary_lines(results):
                print(f"    {line}")
            for f in files:
                print(f"    -> {f}")
    try:
        from .diagnosis import cli as diagnosis_cli
    except ModuleNotFoundError:
        diagnosis_cli = None
    if diagnosis_cli is not None:
        diagnosis_cli.demo(out / "diagnose")
    if getattr(args, "pdf", False):
        from .workbook.pdf import print_books

        t = time.perf_counter()
        pdfs = print_books(sorted(b for b in out.rglob("*.xlsx") if not b.with_suffix(".pdf").exists()))
        print(f"\n[pdf] {len(pdfs)} workbooks printed by LibreOffice ({time.perf_counter() - t:.1f} s)")
        for f in pdfs:
            print(f"    -> {f}")
    print(f"\nDone in {time.perf_counter() - t0:.1f} s. Open the .xlsx files in Excel or LibreOffice; "
          "every number is a formula you can follow back to the inputs.")
    return 0


def cmd_recalc(args) -> int:
    from .workbook.recalc import RecalcError, recalculate, results_rows

    from .workbook.safe_xlsx import MAX_CELLS, MAX_FORMULAS_ENGINE_CELLS, check

    path = Path(args.book)
    if not path.exists():
        raise InputError("no such file", file=path)
    # an untrusted file, checked before either engine sees it: regular file, size, zip bomb,
    # entities in any part, macros, external links, DDE, queries, cell and string counts
    check(path, max_cells=MAX_FORMULAS_ENGINE_CELLS if args.engine == "formulas" else MAX_CELLS)
    try:
        values = recalculate(path, args.engine)
    except RecalcError as e:
        raise InputError(str(e), file=path) from None
    if "Results" not in values:
        raise InputError("no sheet named 'Results'", file=path, where="sheet Results")
    rows = results_rows(values)
    errors = [(k, v) for r in rows for k, v in r.items() if isinstance(v, str) and v.startswith("#")]
    if errors and args.engine == "libreoffice":
        _refuse_circular_references(path)   # LibreOffice shows a cycle only as an error value
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
    from .workbook.recalc import RecalcError, check_no_cycles
    from .workbook.safe_xlsx import MAX_FORMULAS_ENGINE_CELLS, check

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


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cmmwb", formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.fill("Task-specific uncertainty of CMM measurements as live spreadsheet "
                                  "workbooks (Forbes 2025, Wojtyla/Plowucha 2023, Forbes 2022).", 79),
        epilog=examples_epilog("cmmwb demo --out cmmwb-demo",
                         "cmmwb new pointcloud --out gauge.toml && cmmwb build gauge.toml --out gauge",
                         "cmmwb COMMAND --help") +
        "\n\nExit status: 0 success, 2 bad input (one message naming the file and line, key, sheet "
        "or cell),\n1 an internal error. Task files, JSON and workbooks: docs/cli.md.")
    p.add_argument("--version", action="version", version=f"cmmwb {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = add_command(sub, "demo", "build every worked example of the three papers",
                    "Builds the worked examples of the three papers (workbooks, JSON, PNG plots) and the "
                    "mismatch-locator demonstrations into one folder, and prints the headline results.",
                    ("cmmwb demo", "cmmwb demo --out /tmp/demo --pdf"))
    s.add_argument("--out", default="cmmwb-demo", metavar="DIR", help="output folder (default: cmmwb-demo)")
    s.add_argument("--pdf", action="store_true",
                   help="also print every workbook to PDF beside it (needs LibreOffice)")
    s.set_defaults(func=cmd_demo)

    s = add_command(sub, "new", "write a commented task file to start from",
                    "Writes a commented task file of the given kind that builds as it is; a point-cloud "
                    "task comes with its points table TASK_points.csv beside it.",
                    ("cmmwb new pointcloud --out gauge.toml   # also writes gauge_points.csv",
                     "cmmwb new budget --out knuckle.toml", "cmmwb new feature --out bore.toml"))
    s.add_argument("kind", choices=KINDS, help="task kind: " + ", ".join(KINDS))
    s.add_argument("--out", required=True, metavar="TASK.toml", help="task file to write")
    s.add_argument("--force", action="store_true",
                   help="overwrite an existing task file (default: refuse); an existing points table is kept")
    s.set_defaults(func=cmd_new)

    s = add_command(sub, "build", "task file -> workbook + JSON (+ plots)",
                    "Computes the task with the Python core and writes DIR/<name>.xlsx (native formulas), "
                    "DIR/<name>.json and PNG plots, all or nothing; prints the headline results.",
                    ("cmmwb build gauge.toml --out gauge",
                     "cmmwb build gauge.toml --out gauge --force      # after editing the workbook",
                     "cmmwb build bore.toml --out bore --no-plots --cache none",
                     "cmmwb build knuckle.toml --out knuckle --pdf    # and a printed PDF for the audit file"))
    s.add_argument("task", metavar="TASK.toml", help="the task file (see cmmwb new)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    s.add_argument("--no-plots", action="store_true", help="skip the PNG plots (default: write them)")
    s.add_argument("--pdf", action="store_true",
                   help="also print the workbook to DIR/<name>.pdf for the audit file (needs LibreOffice)")
    s.add_argument("--force", action="store_true",
                   help="replace outputs that were edited since cmmwb wrote them, keeping NAME.bak backups "
                        "(default: refuse)")
    s.add_argument("--cache", choices=("results", "all", "none"), default="results",
                   help="cached values for programs that do not calculate: the Results sheet from the "
                        "JSON (default: results), every formula cell as the `formulas` engine computes it "
                        "(all; slow for big workbooks), or none")
    s.add_argument("--exact", action="store_true",
                   help="no approximation: a feature task's V_A by the exact O(m^2) sum even above "
                        "100,000 points (default: the task's [feature] va_method, auto)")
    s.set_defaults(func=cmd_build)

    s = add_command(sub, "recalc", "recompute a workbook headlessly and print its Results",
                    "Recomputes every formula of a workbook with the chosen engine (a forced full "
                    "recalculation) and prints the Results sheet as a table or JSON.",
                    ("cmmwb recalc gauge/my_pointcloud.xlsx",
                     "cmmwb recalc gauge/my_pointcloud.xlsx --engine libreoffice --json"))
    s.add_argument("book", metavar="BOOK.xlsx", help="the workbook (written by cmmwb build, possibly edited)")
    s.add_argument("--engine", choices=("formulas", "libreoffice"), default="formulas",
                   help="formulas: the pure-Python engine, in process (default: formulas); libreoffice: "
                        "a real headless LibreOffice (soffice must be installed)")
    s.add_argument("--json", action="store_true", help="print the Results rows as JSON (default: a table)")
    s.set_defaults(func=cmd_recalc)

    for extra in EXTRA_COMMANDS:
        try:
            mod = importlib.import_module(extra)
        except ModuleNotFoundError as e:
            if e.name != extra:     # the module is there but something it needs is not: say so
                raise
            continue
        mod.register(sub)
    return p


#: exit status when the reader of stdout left (``cmmwb recalc BOOK | head -1``): 128 + SIGPIPE, what
#: the shell reports for any program stopped by a closed pipe; nothing is printed (docs/cli.md)
EXIT_CLOSED_PIPE = 141


def main(argv: list[str] | None = None) -> int:
    try:
        args = parser().parse_args(argv)
    except SystemExit:      # --help, --version, a usage error: printed by argparse
        if _stdout_flushed():
            raise
        return EXIT_CLOSED_PIPE
    previous_hook = sys.unraisablehook
    sys.unraisablehook = _quiet_unraisable
    previous_int = _catch_sigint()
    previous_term = _catch_termination()
    try:
        code = _run(args)
        return code if _stdout_flushed() else EXIT_CLOSED_PIPE
    finally:
        sys.unraisablehook = previous_hook
        if previous_int is not None:
            signal.signal(signal.SIGINT, previous_int)
        for sig, handler in previous_term.items():
            signal.signal(sig, handler)


_interrupted = False


def _on_sigint(signum, frame):
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


def _catch_sigint():
    """Ctrl-C raises KeyboardInterrupt as usual, and is remembered: a library that turns the
    interruption into another exception (matplotlib does) still ends as 'interrupted', 130."""
    global _interrupted
    _interrupted = False
    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            return signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:           # not the main thread
        pass
    return None


_terminated_by = 0


def _on_termination(signum, frame):
    """SIGTERM or SIGHUP (``kill``, a closed terminal): end like Ctrl-C, so that a build removes
    its staging folder instead of leaving it behind; exit status 128 + the signal's number."""
    global _terminated_by
    _terminated_by = signum
    raise KeyboardInterrupt


def _catch_termination() -> dict:
    """Install :func:`_on_termination` for SIGTERM and SIGHUP where they have their default
    disposition; the previous handlers, to restore."""
    global _terminated_by
    _terminated_by = 0
    previous = {}
    for name in ("SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        try:
            if sig is not None and signal.getsignal(sig) is signal.SIG_DFL:
                previous[sig] = signal.signal(sig, _on_termination)
        except ValueError:       # not the main thread
            pass
    return previous


def _run(args) -> int:
    """Run a command; every failure a user can cause is one line on stderr and exit status 2
    (130 for Ctrl-C; a closed output pipe ends quietly), never a traceback."""
    try:
        return args.func(args)
    except InputError as e:
        return _fail(str(e))
    except ModelError as e:
        return _fail(str(e))
    except KeyboardInterrupt:
        print("cmmwb: interrupted", file=sys.stderr)
        return 128 + _terminated_by if _terminated_by else 130
    except BrokenPipeError:
        _silence_stdout()        # `cmmwb recalc book.xlsx | head`: the reader left; nothing to say
        return EXIT_CLOSED_PIPE
    except OSError as e:         # disk full, read-only folder, permission denied, ...
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        return _fail(f"{where}cannot write or read: {os_error_reason(e)}; the previous output is unchanged")
    except MemoryError:
        return _fail("not enough memory for this task (see docs/input_limits.md for the sizes that fit)")
    except RecursionError:
        return _fail("the input is nested too deeply to process")
    except Exception as e:  # a bug: say so plainly
        if _interrupted or _terminated_by:
            print("cmmwb: interrupted", file=sys.stderr)
            return 128 + _terminated_by if _terminated_by else 130
        if os.environ.get("CMMWB_DEBUG"):
            raise
        print(f"cmmwb: internal error ({type(e).__name__}: {e}); rerun with CMMWB_DEBUG=1 for a "
              "traceback and please report it", file=sys.stderr)
        return 1


def _fail(message: str) -> int:
    try:
        print(f"cmmwb: error: {message}", file=sys.stderr)
    except (OSError, ValueError):
        pass
    return 2


def _stdout_flushed() -> bool:
    """Flush stdout now, inside the command, rather than at interpreter exit (where a closed pipe
    is 'Exception ignored ... BrokenPipeError' and exit status 120); False if the reader left."""
    try:
        sys.stdout.flush()
        return True
    except BrokenPipeError:
        _silence_stdout()
        return False
    except (OSError, ValueError, AttributeError):
        return True


def _silence_stdout() -> None:
    """After a broken pipe, point stdout at /dev/null so that flushing at exit raises nothing."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


def _quiet_unraisable(unraisable) -> None:
    """An OSError in a destructor (``ZipFile.__del__`` after a full disk) has already been reported
    as a message; it must not print a traceback too.  A Ctrl-C that landed in a callback whose
    exceptions Python ignores (a weakref callback of the import machinery, a destructor) would be
    lost: it is delivered again, so it surfaces in the command and ends it as 'interrupted'."""
    if isinstance(unraisable.exc_value, OSError):
        return
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        import threading

        # a real SIGINT to the main thread, sent from another thread so that it arrives after this
        # hook has returned (raised in here it would be ignored as well) and wakes a blocking call
        main_thread = threading.main_thread().ident
        threading.Timer(0.01, signal.pthread_kill, (main_thread, signal.SIGINT)).start()
        return
    sys.__unraisablehook__(unraisable)
