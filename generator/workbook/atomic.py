"""Every output is written through here, atomically: a file is either the old one or the complete
new one, never half-written (:func:`replacing`, :func:`write_text`, :func:`write_texts`), and the
files of one run go into their folder all or nothing (:class:`Staging`: build, diagnose, calibrate).
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import signal
import tempfile
import threading
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Iterator

from ..errors import InputError, os_error_reason


@contextmanager
def replacing(path: str | Path, suffix: str = ".tmp") -> Iterator[Path]:
    """A temporary file beside ``path`` to write into; when the block ends without an error it
    replaces ``path`` in one rename (mode 0644), otherwise it is removed and ``path`` is untouched."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except OSError as e:
        if e.filename is not None and Path(e.filename) != Path(tmp):
            raise
        # a full disk while writing the hidden temporary file: said of the file being written
        raise OSError(e.errno, e.strerror, str(path)) from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 text atomically."""
    with replacing(path) as tmp:
        tmp.write_text(text, encoding="utf-8", newline="\n")
    return Path(path)


def write_texts(files: dict[Path, str]) -> None:
    """Write several UTF-8 text files, each atomically; they replace the old files in the order
    given, and only once every one of them is written."""
    with ExitStack() as stack:
        # entered in reverse: the blocks end, and replace their files, in the order given
        tmps = [(stack.enter_context(replacing(path)), text) for path, text in reversed(list(files.items()))]
        for tmp, text in tmps:
            tmp.write_text(text, encoding="utf-8", newline="\n")


def sha256(path: Path) -> str:
    """The SHA-256 of a file, hex (the manifest of :class:`Staging`, the provenance of a build)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


# -- a folder of outputs, all or nothing -----------------------------------------------------------

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


#: the output folders whose commit completed in this process: a signal that ends the command after
#: it (held back during the commit, or arriving just after) is then said to have come after the
#: outputs were written (generator/cli/program.py), not as if nothing had been written
COMMITTED: list[Path] = []


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
                        COMMITTED.append(self.out_dir)
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
                  and manifest.get(f.name) != sha256(self.out_dir / f.name)]
        edited_stale = [n for n in stale if manifest.get(n) != sha256(self.out_dir / n)]
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
            manifest[f.name] = sha256(f)
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
