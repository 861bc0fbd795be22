"""The one guarded read of an input file for the importers: a regular file, at most
``max_bytes``.  (Issue 12 gives every input one public helper for this; this function is the
single place to point at it.)"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import InputError

MAX_IMPORT_BYTES = 256 * 1024 * 1024


def read_input(path: str | Path, max_bytes: int = MAX_IMPORT_BYTES) -> bytes:
    """The bytes of ``path``; a missing file, a directory, a device or pipe, or a file larger
    than ``max_bytes`` is one :class:`InputError` naming the file."""
    path = Path(path)
    try:
        st = os.stat(path)
    except OSError as e:
        raise InputError(f"cannot read the file: {e.strerror}", file=path) from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError("not a regular file", file=path)
    if st.st_size > max_bytes:
        raise InputError(f"larger than {max_bytes // 2**20} MiB ({st.st_size} bytes)", file=path)
    with open(path, "rb") as fh:
        data = fh.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise InputError(f"larger than {max_bytes // 2**20} MiB", file=path)
    return data
