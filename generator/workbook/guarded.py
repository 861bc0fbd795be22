"""The one way cmmwb reads an input file: a regular file of bounded size, checked before parsing.

Every input (task TOML, points CSV, recordings CSV, workbooks, and the importers' files) is read
through :func:`read_bytes` or :func:`open_text`.  They

* open the file without blocking (``O_NONBLOCK``) and refuse anything that is not a regular file
  once opened: a FIFO, a device (``/dev/zero``, ``/dev/stdin``), a socket or a folder would block
  forever or read without end.  Symbolic links are followed (a user may link an input file), but
  what they point at must be a regular file too;
* refuse a file larger than the cap of its kind (:data:`MAX_BYTES`, stated in
  ``docs/input_limits.md``) before reading it, and never read more than the cap even if the file
  grows while it is read;
* turn every ``OSError`` into an :class:`~generator.errors.InputError` naming the file.

``kind`` is one of the keys of :data:`MAX_BYTES`; it also names the file in messages
("the task file", "the points table", ...).
"""

from __future__ import annotations

import io
import os
import stat
from pathlib import Path

from ..errors import InputError

MiB = 2**20

#: size cap per kind of input file, in bytes
MAX_BYTES: dict[str, int] = {
    "task": 16 * MiB,          # a task file (TOML)
    "points": 256 * MiB,       # a points table (CSV)
    "recordings": 256 * MiB,   # a recordings file (CSV)
    "results": 256 * MiB,      # validation results of calibrated workpieces (CSV, cmmwb validate)
    "workbook": 64 * MiB,      # an .xlsx workbook (cmmwb read / recalc)
    "import": 256 * MiB,       # a file of another program's format (importers: QIF scans are large)
}

_WHAT = {"task": "the task file", "points": "the points table", "recordings": "the recordings",
         "results": "the results file",
         "workbook": "the workbook", "import": "the file"}

_NOT_REGULAR = (
    (stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
)


def _cap(kind: str) -> int:
    try:
        return MAX_BYTES[kind]
    except KeyError:
        raise ValueError(f"unknown input kind {kind!r}; one of {', '.join(MAX_BYTES)}") from None


def _describe(mode: int) -> str:
    for test, text in _NOT_REGULAR:
        if test(mode):
            return text
    return "not a regular file"


def _open_regular(path: Path, kind: str) -> int:
    """A file descriptor of ``path`` opened for reading, known to be a regular file within its cap."""
    cap = _cap(kind)
    what = _WHAT[kind]
    if "\x00" in str(path):
        raise InputError(f"cannot read {what}: the file name contains a NUL character", file=repr(str(path)))
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except IsADirectoryError:
        raise InputError(f"{what} is a folder, not a file", file=path) from None
    except FileNotFoundError:
        raise InputError(f"cannot read {what}: no such file", file=path) from None
    except OSError as e:
        raise InputError(f"cannot read {what}: {e.strerror or e}", file=path) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{what} is {_describe(st.st_mode)}, not a regular file: refused", file=path)
        if st.st_size > cap:
            raise InputError(f"{what} is larger than {cap // MiB} MiB ({st.st_size / MiB:.1f} MiB): refused "
                             "(see docs/input_limits.md)", file=path)
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd


def check_regular(path: str | Path, kind: str) -> None:
    """Refuse ``path`` unless it is a regular file within the cap of ``kind`` (nothing is read)."""
    os.close(_open_regular(Path(path), kind))


def read_bytes(path: str | Path, kind: str) -> bytes:
    """The whole content of ``path`` (a regular file, at most the cap of ``kind``)."""
    path = Path(path)
    cap = _cap(kind)
    fd = _open_regular(path, kind)
    try:
        with os.fdopen(fd, "rb", closefd=True) as fh:
            data = fh.read(cap + 1)
    except OSError as e:
        raise InputError(f"cannot read {_WHAT[kind]}: {e.strerror or e}", file=path) from None
    if len(data) > cap:
        raise InputError(f"{_WHAT[kind]} is larger than {cap // MiB} MiB: refused", file=path)
    return data


def read_text(path: str | Path, kind: str) -> str:
    """:func:`read_bytes` decoded as UTF-8 (a leading byte-order mark is dropped); a byte that is
    not UTF-8 is named by its line and offset."""
    path = Path(path)
    raw = read_bytes(path, kind)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        raise InputError(f"not UTF-8 text (byte {e.start}, 0x{raw[e.start]:02x}): save it as UTF-8",
                         file=path, where=f"line {line}") from None


def open_text(path: str | Path, kind: str) -> io.StringIO:
    """The UTF-8 text of ``path`` as a file object (see :func:`read_text`)."""
    return io.StringIO(read_text(path, kind))
