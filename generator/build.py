"""Building a task: load, compute, write the workbook, JSON and plots into a folder, all or
nothing, never over a file someone edited (unless forced, with a backup)."""

from __future__ import annotations

import csv
import errno
import json
import math
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
import warnings
from contextlib import contextmanager
from pathlib import Path

from openpyxl.utils.exceptions import IllegalCharacterError

from xlfuncs.errors import ModelError

from . import decision as decisions
from . import report
from .errors import InputError, os_error_reason
from .jobs import job
from .taskfile import collecting_notes, naming_lines, read_toml, task_kind_and_name
from .workbook import cache as cached_values
from .workbook.atomic import write_text
from .workbook.book import adding_sheets, describing


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


@contextmanager
def _locked(folder: Path):
    """An exclusive lock on ``folder`` (flock on the folder itself: no lock file is left behind)."""
    try:
        import fcntl
    except ImportError:          # not POSIX: no lock (the staging folders still keep runs apart)
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)             # releases the lock


@contextmanager
def _signals_held():
    """Hold back Ctrl-C (SIGINT), SIGTERM and SIGHUP while the block runs, then deliver them."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    old = {}
    for sig in (signal.SIGINT, signal.SIGTERM, *([signal.SIGHUP] if hasattr(signal, "SIGHUP") else [])):
        try:
            old[sig] = signal.signal(sig, lambda s, _f: pending.append(s))
        except (ValueError, OSError):
            pass
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        if pending:
            if signal.SIGINT in pending:
                raise KeyboardInterrupt
            signal.raise_signal(pending[0])


class Staging:
    """A private folder inside DIR; its files move into DIR only when the whole run succeeded.

    Files in DIR that cmmwb did not write, or that changed since cmmwb wrote them (someone edited
    the workbook), are never overwritten: the run fails with a message, unless ``force``, in which
    case each is first renamed to a backup (``NAME.bak``, or ``NAME.<time>.bak`` when that exists).
    What cmmwb wrote is recorded (SHA-256 per file) in ``DIR/.cmmwb-manifest.json``.

    A run only ever removes what it created itself: its own staging folder and, when it fails,
    the folders it created, and only if they are empty (another run may have committed files into
    them meanwhile).  Commits into one DIR are serialised by a lock on DIR (``flock``), and Ctrl-C
    during a commit is held back until the commit is complete, so an interrupted run leaves DIR
    either as it was or with the complete new outputs, never half of them.
    """

    MANIFEST = ".cmmwb-manifest.json"

    def __init__(self, out_dir: Path, *, force: bool = False, task: str | None = None):
        self.out_dir = Path(out_dir)
        self.created = not self.out_dir.exists()
        self.force = force
        #: the task whose outputs these are: the files its previous build wrote and this one does not
        #: write again (a PDF of an earlier ``--pdf`` build) are removed, or kept as backups when edited
        self.task = task
        self.removed: list[Path] = []
        self.backups: list[Path] = []
        self.made_dirs: list[Path] = []     # folders this run created, outermost first

    def __enter__(self) -> Path:
        try:
            with _signals_held():        # a Ctrl-C now is delivered once the state is known
                self._make_folders()
        except BaseException:
            if getattr(self, "tmp", None) is not None:
                shutil.rmtree(self.tmp, ignore_errors=True)
            self._remove_made_dirs()
            raise
        return self.tmp

    def _make_folders(self) -> None:
        self.tmp = None
        missing = []
        d = self.out_dir
        while not d.exists() and d != d.parent:
            missing.append(d)
            d = d.parent
        for d in reversed(missing):
            try:
                d.mkdir()
                self.made_dirs.append(d)
            except FileExistsError:
                pass                        # another run made it meanwhile: not ours to remove
            except OSError as e:
                raise InputError(f"cannot create the output folder: {e.strerror}", file=self.out_dir) from None
        if not self.out_dir.is_dir():
            raise InputError("exists and is not a folder", file=self.out_dir)
        try:
            self.tmp = Path(tempfile.mkdtemp(prefix=".cmmwb-", dir=self.out_dir))
        except OSError as e:
            raise InputError(f"cannot write into the output folder: {e.strerror}", file=self.out_dir) from None

    def __exit__(self, exc_type, exc, tb) -> None:
        with _signals_held():            # commit or clean up completely, then deliver a Ctrl-C
            ok = False
            try:
                if exc_type is None:
                    with _locked(self.out_dir):
                        self._commit()
                        ok = True
            except OSError as e:         # the commit could not write (full disk, ...)
                if not self._writing_failed(e):
                    raise
                exc = e
            finally:
                shutil.rmtree(self.tmp, ignore_errors=True)
                if not ok:
                    self._remove_made_dirs()
        if isinstance(exc, OSError) and self._writing_failed(exc):
            # a full disk, a read-only folder: said of the output folder, not of a staging file
            raise InputError(f"cannot write the outputs into this folder: {os_error_reason(exc)}; "
                             "the previous output is unchanged", file=self.out_dir) from None

    _WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG, errno.EIO,
                               getattr(errno, "EDQUOT", errno.ENOSPC)})

    def _writing_failed(self, e: OSError) -> bool:
        """``e`` is a failure to write into the output folder (rather than, say, a broken pipe)."""
        if e.errno in self._WRITE_ERRNOS:
            return True
        name = getattr(e, "filename", None)
        return name is not None and Path(str(name)).parent in (self.out_dir, self.tmp)

    def _remove_made_dirs(self) -> None:
        """Remove the folders this run created, innermost first, only while they are empty."""
        for d in reversed(self.made_dirs):
            try:
                d.rmdir()
            except OSError:
                break                        # not empty: someone else's files are in it

    def _commit(self) -> None:
        manifest, tasks = self._manifest()
        files = sorted(self.tmp.iterdir())
        new_names = {f.name for f in files}
        # the previous build of this task: what it wrote that this one does not write again
        stale = [n for n in tasks.get(self.task, []) if n not in new_names and (self.out_dir / n).is_file()] \
            if self.task is not None else []
        edited = [f.name for f in files if (self.out_dir / f.name).exists()
                  and manifest.get(f.name) != report.sha256(self.out_dir / f.name)]
        edited_stale = [n for n in stale if manifest.get(n) != report.sha256(self.out_dir / n)]
        if (edited or edited_stale) and not self.force:
            raise InputError("changed since cmmwb wrote it, or not written by cmmwb: not overwritten (use "
                             "--force to replace it and keep a backup, or another --out)",
                             file=self.out_dir / (edited + edited_stale)[0])
        for name in edited + edited_stale:
            self.backups.append(self._backup(self.out_dir / name))
        for name in stale:
            if name not in edited_stale:
                (self.out_dir / name).unlink()
                self.removed.append(self.out_dir / name)
            manifest.pop(name, None)
        for f in files:
            manifest[f.name] = report.sha256(f)
            os.replace(f, self.out_dir / f.name)
        if self.task is not None:
            tasks[self.task] = sorted(new_names)
        write_text(self.out_dir / self.MANIFEST,
                   json.dumps({"format": 1, "files": manifest, "tasks": tasks}, indent=1, sort_keys=True) + "\n")

    def _manifest(self) -> tuple[dict, dict]:
        """(file name -> SHA-256, task name -> the files its last build wrote)."""
        try:
            doc = json.loads((self.out_dir / self.MANIFEST).read_text(encoding="utf-8"))
            files = {str(k): str(v) for k, v in doc["files"].items()}
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            return {}, {}
        tasks = doc.get("tasks") if isinstance(doc, dict) else None
        if not isinstance(tasks, dict):
            tasks = {}
        tasks = {str(k): [str(n) for n in v if isinstance(n, str) and "/" not in n and n not in (".", "..")]
                 for k, v in tasks.items() if isinstance(v, list)}
        return files, tasks

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


def load_task(task_path: Path):
    """Read and validate a task file and its tables: (kind, job module, TOML document, task).
    Every problem is an :class:`InputError` (exit status 2)."""
    task_path = Path(task_path)
    doc = read_toml(task_path)
    with naming_lines(task_path):
        kind, _ = task_kind_and_name(task_path, doc)
    mod = job(kind)
    try:
        with warnings.catch_warnings(), naming_lines(task_path):
            warnings.simplefilter("ignore", RuntimeWarning)
            task = mod.load(task_path, doc)
    except ModelError as e:
        raise InputError(str(e), file=task_path) from None
    except csv.Error as e:  # a malformed points table that the CSV module itself rejects
        raise InputError(f"malformed points table ({e})", file=task_path, where="[points]") from None
    return kind, mod, doc, task


def sheet_writers(kind: str, spec, results: dict, cache: dict) -> list:
    """The sheets every book of the task gets besides its kind's: ``Decision`` (when the task has a
    ``[decision]`` table) and ``Summary``; the values they cache go into ``cache``."""
    rows: dict[str, int] = {}

    def decision_sheet(book):
        got = decisions.write_sheet(book, kind, spec, results, results["decisions"])
        rows.update({t.label: decisions.FIRST_ROW + i for i, t in enumerate(spec.tolerances)})
        for sheet, vals in got.items():
            cache.setdefault(sheet, {}).update(vals)

    def summary_sheet(book):
        got = report.write_sheet(book, kind, results, decision_rows=rows or None,
                                 k_feature=spec.k if spec is not None and spec.k is not None else 2.0)
        for sheet, vals in got.items():
            cache.setdefault(sheet, {}).update(vals)

    return ([decision_sheet] if spec is not None and spec.tolerances else []) + [summary_sheet]


def build_task(task_path: Path, out_dir: Path, *, plots: bool = True, force: bool = False,
               cache: str = "results", exact: bool = False, pdf: bool = False,
               built_utc: str | None = None) -> tuple[dict, list[Path]]:
    """Build one task into ``out_dir``: workbook, JSON and plots, all or nothing.

    ``force``: replace outputs someone edited (keeping backups); ``cache``: which formula cells
    get cached values for programs that do not calculate (see :mod:`generator.workbook.cache`);
    ``exact``: no approximation even for large tasks (the job's ``force_exact``, if it has one:
    a feature task's V_A; the other kinds are always exact); ``pdf``: the workbook printed to PDF by
    LibreOffice, inside the same all-or-nothing commit (so the manifest lists it, and a later build
    without ``pdf`` removes it); ``built_utc``: the build time to record (default: now)."""
    task_path = Path(task_path)
    with collecting_notes() as notes:
        kind, mod, doc, task = load_task(task_path)
        spec = decisions.read_spec(task_path, doc, kind)
        rep = report.read_report(task_path, doc)
    if exact and hasattr(mod, "force_exact"):
        mod.force_exact(task)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)   # numpy's; a non-finite result is caught below
            results = mod.compute(task)
    except ModelError as e:
        raise InputError(str(e), file=task_path) from None
    if spec is not None:
        results["decision_rule"] = decisions.rule_json(spec)
        results["decisions"] = decisions.decide_all(task_path, kind, spec, results)
        if hasattr(mod, "add_type_a"):         # a kind's budgets show the type A inputs (budget)
            mod.add_type_a(results)
    results["provenance"] = report.provenance(task_path, doc, built_utc)
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
        extra_cache: dict = {}
        try:
            with describing({"kind": kind, "name": name, "doc": doc, "task_file": task_path.name}), \
                    adding_sheets(kind, *sheet_writers(kind, spec, results, extra_cache)):
                mod.write_book(task, results, book)
        except IllegalCharacterError:
            raise InputError("a text (a point, probe or characteristic name, or a note) contains a control "
                             "character that a workbook cannot store", file=task_path) from None
        cached_values.store(book, kind, results, cache, extra=extra_cache)
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
