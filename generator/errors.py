"""User-facing input errors: one clear message naming the file and the line, key, sheet or cell."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

from cmmwb.xlfuncs.errors import ModelError


class InputError(Exception):
    """Bad input. ``str(err)`` is the one-line message the CLI prints; exit status 2."""

    def __init__(self, message: str, *, file: str | None = None, where: str | None = None):
        super().__init__(message)
        self.message = message
        self.file = None if file is None else str(file)
        self.where = where

    def __str__(self) -> str:
        loc = ", ".join(str(x) for x in (self.file, self.where) if x)
        return f"{loc}: {self.message}" if loc else self.message


@contextmanager
def model_errors_named(file=None, where: str | None = None) -> Iterator[None]:
    """A :class:`~xlfuncs.errors.ModelError` of the core inside the block becomes an
    :class:`InputError` with its message, naming ``file`` and ``where`` (the traceback of the core
    is dropped: the message says what is wrong)."""
    try:
        yield
    except ModelError as e:
        raise InputError(str(e), file=file, where=where) from None


#: what an errno means for someone whose output could not be written
_OS_HINTS = {28: "the disk is full", 30: "a read-only file system", 13: "permission denied",
             122: "disk quota exceeded", 27: "over the file-size limit"}


def os_error_reason(e: OSError) -> str:
    """The reason of an OSError for a message: ``No space left on device (the disk is full)``."""
    reason = e.strerror or str(e)
    hint = _OS_HINTS.get(e.errno or 0)
    return f"{reason} ({hint})" if hint else reason
