"""CSV tables as spreadsheet programs write them: the one parser behind every CSV cmmwb reads
(points tables, recordings).

What a lab's Excel or LibreOffice exports, and what is accepted:

* the **delimiter** is detected from the header line: comma, semicolon or tab, whichever splits
  it into the most fields (a tie goes to comma, then semicolon); European Excel writes semicolons;
* **decimal commas** (``12,5``) are read as decimal points where that is unambiguous: in
  semicolon- or tab-separated files (in a comma-separated file a decimal comma splits the field
  and the row has too many fields);
* **header names** match the known column names ignoring case (``ID,X,Y,Z``);
* **empty columns** (no name in the header and no value in any row, as an Excel range with
  empty columns at its right is exported: ``id,x,...,probe,,``) are dropped; an unnamed column
  that holds a value is an error naming the line; when the unnamed columns are the header's
  last ones, a row may also end without them.

Lines starting with ``#`` (and blank lines) before the header are comments.  What was detected
beyond a plain comma-separated file is said in :attr:`Table.notes`, for the command to print.
Stdlib only; errors are :class:`TableError` with the 1-based file line.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from typing import Iterable, Iterator

DELIMITERS = {",": "comma", ";": "semicolon", "\t": "tab"}
_DECIMAL_COMMA = re.compile(r"^\s*[+-]?(\d+,\d*|,\d+)([eE][+-]?\d+)?\s*$")


class TableError(ValueError):
    """A malformed table: ``line`` (1-based line of the file) and ``column`` (header name)."""

    def __init__(self, message: str, line: int | None = None, column: str | None = None):
        super().__init__(message)
        self.message, self.line, self.column = message, line, column


@dataclass
class Table:
    """A CSV table's header and the text of its records (see the module's docstring)."""

    header: tuple[str, ...]          # the named columns, known names in their canonical spelling
    header_line: int                 # 1-based line of the header in the file
    delimiter: str
    comments: tuple[str, ...]        # comment lines before the header, without the '#'
    notes: list[str] = field(default_factory=list)
    _lines: list[str] = field(default_factory=list, repr=False)
    _start: int = 0                  # 0-based index of the header line
    _keep: tuple[int, ...] = ()      # indices of the named columns in the file's fields
    _width: int = 0                  # number of fields of the file's header line

    @property
    def _trailing_unnamed(self) -> bool:
        """The unnamed columns are all at the right end of the header."""
        return self._keep == tuple(range(len(self._keep)))

    @property
    def decimal_comma(self) -> bool:
        """Decimal commas are accepted (semicolon- or tab-separated files)."""
        return self.delimiter != ","

    def number(self, text: str) -> float:
        """``text`` as a float; a decimal comma is a decimal point where accepted.  ValueError else."""
        t = text.strip()
        if self.decimal_comma and _DECIMAL_COMMA.match(t):
            t = t.replace(",", ".")
        return float(t)

    def records(self) -> Iterator[tuple[int, tuple[str, ...]]]:
        """(file line, fields of the named columns) of each non-blank record.  A record with another
        number of fields than the header, or with a value in an unnamed column, is a TableError."""
        reader = csv.reader(io.StringIO("\n".join(self._lines[self._start:])), delimiter=self.delimiter)
        next(reader)
        named = len(self._keep)
        while True:
            try:
                row = next(reader)
            except StopIteration:
                return
            except csv.Error as e:
                raise TableError(f"malformed CSV: {e}", self._start + reader.line_num) from None
            line = self._start + reader.line_num
            if not row or all(not c.strip() for c in row):
                continue
            if self._trailing_unnamed and named <= len(row) < self._width:
                row = row + [""] * (self._width - len(row))    # a row without the header's empty tail
            if len(row) != self._width:
                hint = (" (a decimal comma in a comma-separated file?)"
                        if self.delimiter == "," and len(row) > self._width else "")
                raise TableError(f"{len(row)} fields, the header has {self._width}{hint}", line)
            if named != self._width:
                for k, v in enumerate(row):
                    if v.strip() and k not in self._keep:
                        raise TableError(f"a value ({v.strip()[:20]!r}) in column {k + 1}, which has no "
                                         f"name in the header (line {self.header_line})", line)
                row = [row[k] for k in self._keep]
            yield line, tuple(row)


def _delimiter(header_line: str) -> str:
    best, best_n = ",", 0
    for d in DELIMITERS:          # comma first: a tie keeps the comma
        n = len(next(csv.reader([header_line], delimiter=d), []))
        if n > best_n:
            best, best_n = d, n
    return best


def read_table(text: str, known: Iterable[str] = ()) -> Table:
    """Parse ``text`` (the file's content) into a :class:`Table`; ``known``: the column names the
    reader knows, matched ignoring case.  Raises :class:`TableError`."""
    lines = text.splitlines()
    start = 0
    comments = []
    while start < len(lines) and (lines[start].lstrip().startswith("#") or not lines[start].strip()):
        if lines[start].strip():
            comments.append(lines[start].lstrip()[1:].strip())
        start += 1
    if start == len(lines):
        raise TableError("no header line")
    header_line = start + 1
    delimiter = _delimiter(lines[start])
    try:
        raw = next(csv.reader(io.StringIO("\n".join(lines[start:])), delimiter=delimiter))
    except csv.Error as e:
        raise TableError(f"malformed CSV: {e}", header_line) from None
    raw = [h.strip() for h in raw]
    notes = []
    if delimiter != ",":
        notes.append(f"read as {DELIMITERS[delimiter]}-separated (detected from the header), "
                     "decimal commas accepted")
    keep = tuple(k for k, h in enumerate(raw) if h)
    if len(keep) < len(raw):
        unnamed = [str(k + 1) for k, h in enumerate(raw) if not h]
        notes.append(f"column{'s' if len(unnamed) > 1 else ''} {', '.join(unnamed)} without a name in the "
                     f"header and without values: ignored")
    canonical: dict[str, str] = {}
    for name in known:
        canonical.setdefault(name.casefold(), name)
    header, renamed = [], []
    for k in keep:
        h = canonical.get(raw[k].casefold(), raw[k])
        if h != raw[k]:
            renamed.append(f"{raw[k]!r} as {h!r}")
        header.append(h)
    if renamed:
        notes.append("header names matched ignoring case: " + ", ".join(renamed))
    for k, h in enumerate(header):
        if h in header[:k]:
            raise TableError(f"column {h!r} appears twice in the header", header_line, h)
    return Table(tuple(header), header_line, delimiter, tuple(comments), notes, lines, start, keep, len(raw))
