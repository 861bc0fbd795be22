"""The ``cmmwb`` command line (thin: parsing, output folders, error reporting).

Exit status: 0 success, 2 bad input (one message naming the file and line/key/sheet/cell),
1 an internal error (a bug: please report it with the task file).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

from xlfuncs.errors import ModelError

from . import __version__
from .atomic import write_text
from .errors import InputError
from .jobs import available, job
from .taskfile import KINDS, read_toml, task_kind_and_name

EXAMPLES_DIR = Path(__file__).parent / "examples"


class _Staging:
    """A private folder inside DIR; its files move into DIR only when the whole run succeeded.

    Files in DIR that cmmwb did not write, or that changed since cmmwb wrote them (someone edited
    the workbook), are never overwritten: the run fails with a message, unless ``force``, in which
    case each is first renamed to a backup (``NAME.bak``, or ``NAME.<time>.bak`` when that exists).
    What cmmwb wrote is recorded (SHA-256 per file) in ``DIR/.cmmwb-manifest.json``.
    """

    MANIFEST = ".cmmwb-manifest.json"

    def __init__(self, out_dir: Path, *, force: bool = False):
        self.out_dir = Path(out_dir)
        self.created = not self.out_dir.exists()
        self.force = force
        self.backups: list[Path] = []

    def __enter__(self) -> Path:
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(f"cannot create the output folder: {e.strerror}", file=self.out_dir) from None
        self.tmp = Path(tempfile.mkdtemp(prefix=".cmmwb-", dir=self.out_dir))
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> None:
        ok = False
        try:
            if exc_type is None:
                self._commit()
            ok = exc_type is None
        finally:
            shutil.rmtree(self.tmp, ignore_errors=True)
            if not ok and self.created:
                shutil.rmtree(self.out_dir, ignore_errors=True)

    def _commit(self) -> None:
        manifest = self._manifest()
        files = sorted(self.tmp.iterdir())
        edited = [f.name for f in files if (self.out_dir / f.name).exists()
                  and manifest.get(f.name) != self._sha256(self.out_dir / f.name)]
        if edited and not self.force:
            raise InputError("changed since cmmwb wrote it, or not written by cmmwb: not overwritten (use "
                             "--force to replace it and keep a backup, or another --out)",
                             file=self.out_dir / edited[0])
        for name in edited:
            self.backups.append(self._backup(self.out_dir / name))
        for f in files:
            manifest[f.name] = self._sha256(f)
            os.replace(f, self.out_dir / f.name)
        tmp = self.out_dir / f".{self.MANIFEST}.tmp"
        tmp.write_text(json.dumps({"format": 1, "files": manifest}, indent=1, sort_keys=True) + "\n",
                       encoding="utf-8")
        os.replace(tmp, self.out_dir / self.MANIFEST)

    def _manifest(self) -> dict:
        try:
            files = json.loads((self.out_dir / self.MANIFEST).read_text(encoding="utf-8"))["files"]
            return {str(k): str(v) for k, v in files.items()}
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            return {}

    @staticmethod
    def _sha256(path: Path) -> str:
        import hashlib

        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        return h.hexdigest()

    @staticmethod
    def _backup(path: Path) -> Path:
        """Rename ``path`` to a backup name that does not exist yet; return it."""
        bak = path.with_name(path.name + ".bak")
        if bak.exists():
            stamp = time.strftime("%Y%m%d-%H%M%S")
            bak = path.with_name(f"{path.name}.{stamp}.bak")
            n = 1
            while bak.exists():
                bak = path.with_name(f"{path.name}.{stamp}-{n}.bak")
                n += 1
        os.replace(path, bak)
        return bak


def build_task(task_path: Path, out_dir: Path, *, plots: bool = True, force: bool = False,
               cache: str = "results") -> tuple[dict, list[Path]]:
    """Build one task into ``out_dir``: workbook, JSON and plots, all or nothing.

    ``force``: replace outputs someone edited (keeping backups); ``cache``: which formula cells
    get cached values for programs that do not calculate (see :mod:`generator.cache`)."""
    import csv
    import math
    import warnings

    from openpyxl.utils.exceptions import IllegalCharacterError

    from . import cache as cached_values
    from .book import describing

    task_path = Path(task_path)
    doc = read_toml(task_path)
    kind, _ = task_kind_and_name(task_path, doc)
    mod = job(kind)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)   # numpy's; a non-finite result is caught below
            task = mod.load(task_path, doc)
            results = mod.compute(task)
    except ModelError as e:
        raise InputError(str(e), file=task_path) from None
    except csv.Error as e:  # a malformed points table that the CSV module itself rejects
        raise InputError(f"malformed points table ({e})", file=task_path, where="[points]") from None
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

    bad = non_finite(results)
    if bad is not None:
        raise InputError(f"the model gives {bad[1]!r} for {bad[0]}: check the inputs for extreme values "
                         "(e.g. a length scale so small that its square underflows)", file=task_path)
    staging = _Staging(out_dir, force=force)
    with staging as tmp:
        name = results["name"]
        book = tmp / f"{name}.xlsx"
        try:
            with describing({"kind": kind, "name": name, "doc": doc, "task_file": task_path.name}):
                mod.write_book(task, results, book)
        except IllegalCharacterError:
            raise InputError("a text (a point, probe or characteristic name, or a note) contains a control "
                             "character that a workbook cannot store", file=task_path) from None
        cached_values.store(book, kind, results, cache)
        (tmp / f"{name}.json").write_text(json.dumps(results, indent=1, ensure_ascii=False) + "\n",
                                          encoding="utf-8")
        made = [tmp / f"{name}.xlsx", tmp / f"{name}.json"]
        if plots:
            made += list(mod.write_plots(task, results, tmp))
    for b in staging.backups:
        print(f"cmmwb: kept a backup of the replaced file: {b}", file=sys.stderr)
    return results, [Path(out_dir) / p.name for p in made]


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
            print("\t".join(f"{v:.6g}" if isinstance(v, float) else str(v) for v in r.values()))
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

    for extra in ("read_cli", "diagnose_cli"):
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
