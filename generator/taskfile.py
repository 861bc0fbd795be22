"""Reading and validating task files (TOML): the file itself (size, depth, the line of a key),
file names, the kind and name of a task, typed getters of keys, and the notes (warnings) collected
while reading.  The point-cloud model every kind shares ([parameters], [[probes]], [points]) is read
by :mod:`generator.taskcloud` with these getters.

Every problem becomes one :class:`~generator.errors.InputError` naming the file and the key or
line, so the CLI can print it and exit with status 2.
"""

from __future__ import annotations

import math
import re
import tomllib
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Iterator

from cmmwb.xlfuncs.limits import coordinate_problem, plausibility_problem

from .errors import InputError
from .workbook.guarded import MAX_BYTES, read_text

KINDS = ("pointcloud", "budget", "feature", "characteristic")
MAX_TASK_BYTES = MAX_BYTES["task"]
#: tables every task kind accepts, read by the build itself: conformity decisions and report fields
#: the tables every kind accepts: decisions, report fields, the part's temperature (the factor W)
COMMON_TABLES = frozenset({"decision", "report", "workpiece"})


MAX_DEPTH = 16           # tables and arrays nested deeper than this are refused
MAX_INT = 2**63 - 1      # TOML integers are 64-bit (TOML 1.0, "Integer")


_NOTES: ContextVar[list[str] | None] = ContextVar("cmmwb_input_notes", default=None)


@contextmanager
def collecting_notes() -> Iterator[list[str]]:
    """Collect what the readers :func:`note` while the block runs (a build prints the notes on
    stderr and lists them in its JSON ``warnings``)."""
    notes: list[str] = []
    token = _NOTES.set(notes)
    try:
        yield notes
    finally:
        _NOTES.reset(token)


def note(message: str, *, file=None, where: str | None = None) -> None:
    """Something the user should know about an accepted input (what was detected in a CSV file,
    an implausible value): one line naming the file and the place, like an :class:`InputError`.
    Kept once, in the order noted, when notes are being collected; dropped otherwise."""
    notes = _NOTES.get()
    text = str(InputError(message, file=file, where=where))
    if notes is not None and text not in notes:
        notes.append(text)


def read_toml(path: Path) -> dict:
    """Parse a task file; syntax errors name the line (tomllib reports line and column).

    Read through :func:`generator.workbook.guarded.read_text` (a regular file of at most 16 MiB, UTF-8; a
    byte-order mark is accepted).  Integers beyond 64 bits and nesting deeper than
    :data:`MAX_DEPTH` are refused with the key that holds them."""
    path = Path(path)
    text = read_text(path, "task")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"malformed TOML: {e}", file=path) from None
    except RecursionError:
        raise InputError(f"malformed TOML: arrays or tables nested too deeply (at most {MAX_DEPTH} levels)",
                         file=path, where=_too_deep(text)) from None
    except ValueError as e:   # an integer of more than 4300 digits (Python's own limit)
        raise InputError(f"malformed TOML: an integer too large ({str(e).split(':')[0]})", file=path) from None
    with naming_lines(path, text):
        _check_structure(path, doc, "", 0)
    return doc


_TABLE_HEADER = re.compile(r"^\s*\[\[?\s*([^\]]*?)\s*\]\]?\s*(#.*)?$")
_DEEP_KEY = re.compile(r"^\s*([^=\[{#]+?)\s*=")


def _too_deep(text: str) -> str | None:
    """Where arrays or inline tables first nest deeper than :data:`MAX_DEPTH` (``line N, key K``
    with the key under its table), found in the text: the parser itself only ran out of stack."""
    depth, table, key, quote = 0, "", None, None
    for n, line in enumerate(text.splitlines(), start=1):
        if depth == 0 and quote is None:
            m = _TABLE_HEADER.match(line)
            if m:
                table = m.group(1).strip()
                continue
            m = _DEEP_KEY.match(line)
            if m:
                key = f"{table}.{m.group(1).strip()}" if table else m.group(1).strip()
        k = 0
        while k < len(line):
            c = line[k]
            if quote is not None:
                if c == "\\" and quote == '"':
                    k += 1
                elif c == quote:
                    quote = None
            elif c in "\"'":
                quote = c
            elif c == "#":
                break
            elif c in "[{":
                depth += 1
                if depth > MAX_DEPTH:
                    return f"line {n}" + (f", key {key}" if key else "")
            elif c in "]}":
                depth = max(depth - 1, 0)
            k += 1
        if quote == "'":            # literal strings end with their line; so do basic ones
            quote = None
        if quote == '"':
            quote = None
    return None


# -- the line of a key ------------------------------------------------------------------------------

#: the place an InputError names: ``[table] key``, ``[[array]] #n key 'k'``, ``[[[array]] #n] key``,
#: ``[points] rows #3 key 'x'``, or the dotted ``table.key[2]`` of the structure check
_WHERE = re.compile(r"^\[+\s*(?P<table>[^\]\s#]+)\s*\]+\s*(?:#(?P<index>\d+)\]?)?\s*(?:key\s+)?"
                    r"['\"]?(?P<key>[A-Za-z0-9_\-]+)?")
_HEADER = re.compile(r"^\s*(?P<open>\[\[?)\s*(?P<name>[A-Za-z0-9_\-]+|\"[^\"]*\")\s*\]\]?")
_KEY = re.compile(r"^\s*(?P<key>[A-Za-z0-9_\-]+|\"[^\"]*\"|'[^']*')\s*[=.]")


def key_line(text: str, where: str) -> int | None:
    """The line (1-based) of the TOML source ``text`` that holds the key named by ``where`` (as
    the readers name places: ``[parameters] sigma_R_um``, ``[[probes]] #2 offset_mm``,
    ``[[characteristics]] #3 key 'model'``, ``parameters.sigma_R_um``); the line of its table's
    header when the key itself is not written (a missing key), None when neither is found.

    tomllib keeps no positions, so the source is scanned: table headers (``[t]``, ``[[t]]``
    counted per name) and ``key =`` at the start of a line; a table written inline at the top
    level (``t = {...}``) or as dotted keys (``t.k = ...``) is found by its first line."""
    m = _WHERE.match(where)
    if m:
        table, index, key = m["table"], m["index"], m["key"]
    else:
        parts = re.split(r"[.\[]", where)
        if len(parts) < 1 or not parts[0]:
            return None
        table, index, key = parts[0], None, (parts[1].rstrip("]") if len(parts) > 1 else None)
        if key is not None and key.isdigit():   # table[2].k: the third table of an array
            index, key = str(int(key) + 1), (parts[2] if len(parts) > 2 else None)
    index = int(index) if index else None
    current, count, header_line = None, {}, None
    for n, line in enumerate(text.splitlines(), start=1):
        h = _HEADER.match(line)
        if h:
            name = h["name"].strip('"')
            count[name] = count.get(name, 0) + 1
            current = (name, count[name] if h["open"] == "[[" else None)
            if name == table and (index is None or current[1] == index):
                header_line = n
            continue
        k = _KEY.match(line)
        if k is None:
            continue
        found = k["key"].strip("\"'")
        if current is None and found == table:
            if key is None or header_line is None:
                header_line = header_line or n   # t = {...} or t.k = ... at the top level
            if key is not None and re.match(rf"^\s*{re.escape(k['key'])}\s*\.\s*{re.escape(key)}\s*=", line):
                return n
        elif current is not None and current[0] == table and (index is None or current[1] == index) \
                and key is not None and found == key:
            return n
    return header_line


@contextmanager
def naming_lines(path: Path, text: str | None = None):
    """Inside this block, an :class:`InputError` about the task file ``path`` that names a key
    also names its line (``[parameters] sigma_R_um (line 14)``), as the README promises."""
    try:
        yield
    except InputError as e:
        add_line(e, path, text)
        raise


def add_line(err: InputError, path: Path, text: str | None = None) -> None:
    """Append ``(line N)`` to ``err.where`` when it names a key of the TOML file ``path``."""
    if err.file != str(path) or not err.where or re.search(r"\bline \d+", err.where):
        return
    if text is None:
        try:
            text = read_text(Path(path), "task")
        except (InputError, OSError):
            return
    n = key_line(text, err.where)
    if n is not None:
        err.where = f"{err.where} (line {n})"


def place(path: Path, where: str) -> str:
    """``where`` with the line of its key in the task file ``path`` (``[[frames]] #1 name (line
    80)``), as an error message names a second place besides its own."""
    err = InputError("", file=path, where=where)
    add_line(err, path)
    return err.where or where


class Names:
    """One namespace of names a task file defines (features, frames, characteristics, probes
    ...): the place where each name was first given.  A name given twice is an
    :class:`InputError` naming the file and both places, never the second silently replacing the
    first."""

    def __init__(self, path: Path, what: str):
        self.path, self.what = Path(path), what
        self.first: dict[str, str] = {}

    def add(self, name: str, where: str) -> str:
        if name in self.first:
            raise InputError(f"{self.what} {name!r} is given twice: here and at "
                             f"{place(self.path, self.first[name])}; give each {self.what} its own name",
                             file=self.path, where=where)
        self.first[name] = where
        return name

    def __contains__(self, name: object) -> bool:
        return name in self.first

    def where(self, name: str) -> str:
        return self.first[name]


def _table_key(where: str) -> str:
    """The dotted place of :func:`_check_structure` as the readers name places: ``report.lab`` ->
    ``[report] lab``, ``characteristics[2].name`` -> ``[[characteristics]] #3 name``; others as
    they are."""
    m = re.fullmatch(r"([A-Za-z0-9_\-]+)(?:\[(\d+)\])?\.([A-Za-z0-9_\-]+)", where)
    if m is None:
        return where
    if m.group(2) is None:
        return f"[{m.group(1)}] {m.group(3)}"
    return f"[[{m.group(1)}]] #{int(m.group(2)) + 1} {m.group(3)}"


#: the characters a workbook cannot store (XML 1.0 allows tab, line feed and carriage return only)
_UNSTORABLE = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f]")


def _check_structure(path: Path, value, where: str, depth: int) -> None:
    """Refuse integers beyond 64 bits, nesting deeper than MAX_DEPTH and texts holding a control
    character a workbook cannot store (any text of a task may reach a cell), naming the key."""
    if depth > MAX_DEPTH:
        raise InputError(f"nested deeper than {MAX_DEPTH} levels of arrays or tables", file=path,
                         where=where or None)
    if isinstance(value, bool):
        return
    if isinstance(value, str):
        bad = _UNSTORABLE.search(value)
        if bad is not None:
            what = "a NUL character (0x00)" if bad.group() == "\x00" else f"the control character {ord(bad.group()):#04x}"
            raise InputError(f"holds {what}, which a workbook cannot store (XML 1.0): remove it", file=path,
                             where=_table_key(where) or None)
        return
    if isinstance(value, int):
        if abs(value) > MAX_INT:
            raise InputError(f"an integer of {len(str(abs(value)))} digits: larger than TOML's 64-bit "
                             "integers (write it as a float, e.g. 1e30)", file=path, where=where or None)
        return
    if isinstance(value, dict):
        for k, v in value.items():
            _check_structure(path, v, f"{where}.{k}" if where else str(k), depth + 1)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_structure(path, v, f"{where}[{i}]", depth + 1)


#: characters that must not reach a file name: control characters (C0, DEL, C1) and the
#: bidirectional embedding/override/isolate marks (the "U+202E" file-name spoof)
_BIDI = {chr(c) for c in (*range(0x202A, 0x202F), *range(0x2066, 0x206A), 0x200E, 0x200F, 0x061C)}
_RESERVED = {"CON", "PRN", "AUX", "NUL", *(f"COM{k}" for k in range(1, 10)), *(f"LPT{k}" for k in range(1, 10)),
             "COM\u00b9", "COM\u00b2", "COM\u00b3", "LPT\u00b9", "LPT\u00b2", "LPT\u00b3"}
MAX_NAME_CHARS = 100
MAX_NAME_BYTES = 180     # UTF-8 bytes: leaves room for suffixes such as _distances.png within 255


def file_name_problem(name: str) -> str | None:
    """Why ``name`` cannot become a file name (on Linux, macOS and Windows), or None."""
    if not name:
        return "is empty"
    if "\x00" in name:
        return "holds a NUL character (0x00)"
    ctrl = next((ch for ch in name if ord(ch) < 32 or 127 <= ord(ch) < 160), None)
    if ctrl is not None:
        return f"holds a control character ({ord(ctrl):#04x})"
    bidi = next((ch for ch in name if ch in _BIDI), None)
    if bidi is not None:
        return (f"holds the bidirectional-text control U+{ord(bidi):04X}, which can disguise a file name "
                "(e.g. make 'exe.xlsx' look like 'xlsx.exe')")
    bad = next((ch for ch in name if ch in '/\\:*?"<>|'), None)
    if bad is not None:
        return f"holds {bad!r}, which a file name cannot hold"
    if name.startswith("."):
        return "starts with '.' (a hidden file)"
    if name != name.strip() or name.endswith("."):
        return "starts or ends with a space, or ends with '.' (Windows drops those)"
    if name.split(".")[0].strip().upper() in _RESERVED:
        return f"is a reserved device name on Windows ({name.split('.')[0].upper()})"
    if len(name) > MAX_NAME_CHARS:
        return f"is longer than {MAX_NAME_CHARS} characters ({len(name)})"
    if len(name.encode("utf-8")) > MAX_NAME_BYTES:
        return f"is longer than {MAX_NAME_BYTES} bytes in UTF-8 ({len(name.encode('utf-8'))})"
    return None


def task_kind_and_name(path: Path, doc: dict) -> tuple[str, str]:
    task = table(path, doc, "task")
    kind = string(path, task, "task", "kind")
    if kind not in KINDS:
        raise InputError(f"unknown kind {kind!r}; expected one of {', '.join(KINDS)}", file=path,
                         where="[task] kind")
    name = string(path, task, "task", "name")
    problem = file_name_problem(name)
    if problem is not None:
        raise InputError(f"{name[:60]!r} is not usable as a file name: it {problem}", file=path,
                         where="[task] name")
    return kind, name


# -- typed getters ---------------------------------------------------------------------------

def table(path: Path, doc: dict, key: str, required: bool = True) -> dict:
    value = doc.get(key)
    if value is None:
        if required:
            raise InputError(f"missing table [{key}]", file=path, where=f"[{key}]")
        return {}
    if not isinstance(value, dict):
        raise InputError(f"[{key}] must be a table", file=path, where=f"[{key}]")
    return value


def string(path: Path, tbl: dict, section: str, key: str, default: str | None = None) -> str:
    value = tbl.get(key, default)
    if value is None:
        raise InputError("missing key", file=path, where=f"[{section}] {key}")
    if not isinstance(value, str):
        raise InputError(f"must be text, got {value!r}", file=path, where=f"[{section}] {key}")
    return value


def number(path: Path, tbl: dict, section: str, key: str, default: float | None = None, *,
           lo: float | None = None, positive: bool = False) -> float:
    """A finite number (ints and floats; booleans and strings are errors)."""
    value = tbl.get(key, default)
    where = f"[{section}] {key}"
    if value is None:
        raise InputError("missing key", file=path, where=where)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"must be a number, got {value!r}", file=path, where=where)
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"must be a finite number, got {value!r}", file=path, where=where)
    if lo is not None and value < lo:
        raise InputError(f"must be >= {lo:g}, got {value:g}", file=path, where=where)
    if positive and value <= 0:
        raise InputError(f"must be positive, got {value:g}", file=path, where=where)
    problem = plausibility_problem(key, value) if key in tbl else None
    if problem:
        note(problem, file=path, where=where)
    return value


def text_list(path: Path, tbl: dict, section: str, key: str) -> list[str]:
    """A text or a list of texts (e.g. ``[task] notes``); absent gives []."""
    value = tbl.get(key, [])
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise InputError("must be text or a list of texts", file=path, where=f"[{section}] {key}")
    return list(value)


def vector3(path: Path, tbl: dict, section: str, key: str) -> tuple[float, float, float]:
    value = tbl.get(key)
    where = f"{section} {key}"
    if not isinstance(value, list) or len(value) != 3:
        raise InputError("must be a list of three numbers [x, y, z]", file=path, where=where)
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise InputError(f"must be three finite numbers, got {value!r}", file=path, where=where)
        if key.endswith("_mm") and coordinate_problem(float(v)) is not None:
            raise InputError(coordinate_problem(float(v)), file=path, where=where)
        out.append(float(v))
    return tuple(out)  # type: ignore[return-value]


def check_keys(path: Path, tbl: dict, section: str, allowed: set[str]) -> None:
    """Unknown keys are errors: a typo must not silently become a zero parameter."""
    for key in tbl:
        if key not in allowed:
            raise InputError(f"unknown key (expected one of {', '.join(sorted(allowed))})",
                             file=path, where=f"[{section}] {key}")
