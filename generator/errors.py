"""User-facing input errors: one clear message naming the file and the line, key, sheet or cell."""


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
