"""Reading and validating task files (TOML) and point tables (CSV).

Every problem becomes one :class:`~generator.errors.InputError` naming the file and the key or
line, so the CLI can print it and exit with status 2.
"""

from __future__ import annotations

import math
import re
import tomllib
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from cmmwb.xlfuncs.csvtable import TableError
from cmmwb.xlfuncs.csvtable import read_table as read_csv_table
from cmmwb.xlfuncs.limits import PLAUSIBLE, coordinate_problem, plausibility_problem
from cmmwb.xlfuncs.pointcloud import Parameters, PointCloud, Probe

from .errors import InputError, model_errors_named
from .workbook.guarded import MAX_BYTES, read_text

KINDS = ("pointcloud", "budget", "feature", "characteristic")
MAX_TASK_BYTES = MAX_BYTES["task"]
MAX_CSV_BYTES = MAX_BYTES["points"]
NORMAL_TOL = 1e-3
#: tables every task kind accepts, read by the build itself: conformity decisions and report fields
COMMON_TABLES = frozenset({"decision", "report"})


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


def _check_structure(path: Path, value, where: str, depth: int) -> None:
    """Refuse integers beyond 64 bits and nesting deeper than MAX_DEPTH, naming the key."""
    if depth > MAX_DEPTH:
        raise InputError(f"nested deeper than {MAX_DEPTH} levels of arrays or tables", file=path,
                         where=where or None)
    if isinstance(value, bool):
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


# -- the point-cloud model: [parameters], [[probes]], [points] --------------------------------

PARAMETER_KEYS = tuple(Parameters.__dataclass_fields__)
PROBE_OVERRIDES = ("sigma_PQ_um", "sigma_P0_um", "sigma_P_um", "lambda_P")


def read_parameters(path: Path, doc: dict) -> Parameters:
    tbl = table(path, doc, "parameters", required=False)
    check_keys(path, tbl, "parameters", set(PARAMETER_KEYS))
    values = {k: number(path, tbl, "parameters", k, 0.0, lo=0.0) for k in PARAMETER_KEYS}
    with model_errors_named(file=path, where="[parameters]"):
        return Parameters(**values)


#: what a missing probe offset means (a warning, docs/input_limits.md "Plausible values")
NO_OFFSET = ("the stylus tip at the ram's reference point: the rotation errors (ER, Forbes 2025 eq. (25)) act "
             "through the offset and then contribute nothing; give the probe's offset_mm")


def read_probes(path: Path, doc: dict) -> tuple[Probe, ...]:
    raw = doc.get("probes")
    if raw is None:
        er = doc.get("parameters", {}).get("sigma_ER_urad", 0) if isinstance(doc.get("parameters"), dict) else 0
        if isinstance(er, (int, float)) and not isinstance(er, bool) and er > 0:
            note(f"no [[probes]]: one probe P1 with offset [0, 0, 0] mm is assumed, {NO_OFFSET}", file=path,
                 where="[[probes]]")
        return (Probe("P1"),)
    if not isinstance(raw, list) or not raw or not all(isinstance(p, dict) for p in raw):
        raise InputError("must be one or more [[probes]] tables", file=path, where="[[probes]]")
    probes = []
    seen = set()
    for n, p in enumerate(raw, start=1):
        section = f"[[probes]] #{n}"
        check_keys(path, p, section, {"id", "offset_mm", *PROBE_OVERRIDES})
        pid = check_label(string(path, p, section, "id").strip(), path, f"{section} id")
        if pid in seen:
            raise InputError(f"probe id {pid!r} used twice", file=path, where=f"{section} id")
        seen.add(pid)
        if "offset_mm" in p:
            offset = vector3(path, p, section, "offset_mm")
            length = math.sqrt(sum(v * v for v in offset))
            if plausibility_problem("offset_mm", length):
                note(f"offset_mm {list(offset)} is {length:g} mm long, longer than any stylus or ram offset "
                     f"of a CMM (at most {PLAUSIBLE['offset_mm'][1]:g} mm); built as given -- is it in mm?",
                     file=path, where=f"{section} (probe {pid}) offset_mm")
        else:
            offset = (0.0, 0.0, 0.0)
            note(f"probe {pid} has no offset_mm: taken as [0, 0, 0] mm, {NO_OFFSET}", file=path,
                 where=f"{section} (probe {pid})")
        over = {k: number(path, p, section, k, lo=0.0) for k in PROBE_OVERRIDES if k in p}
        probes.append(Probe(pid, offset, **over))
    return tuple(probes)


MAX_LABEL = 100


def check_label(label: str, path: Path, where: str) -> str:
    """A point or probe label: not empty, at most 100 characters, no control characters.
    (Labels that start with =, +, - or @ are fine: they are always written as text.)"""
    if not label:
        raise InputError("empty label", file=path, where=where)
    if len(label) > MAX_LABEL:
        raise InputError(f"label longer than {MAX_LABEL} characters", file=path, where=where)
    bad = [ch for ch in label if ord(ch) < 32 or ord(ch) == 127]
    if bad:
        raise InputError(f"label {label[:40]!r} holds a control character ({ord(bad[0]):#04x})",
                         file=path, where=where)
    return label


@dataclass(frozen=True)
class PointTable:
    labels: tuple[str, ...]
    X_mm: np.ndarray
    N: np.ndarray
    probe_ids: tuple[str, ...]
    lines: tuple[int, ...]  # line of each point in its file (for messages)


POINT_COLUMNS = {
    "id": ("id",), "x": ("x", "x_mm"), "y": ("y", "y_mm"), "z": ("z", "z_mm"),
    "nx": ("nx",), "ny": ("ny",), "nz": ("nz",), "probe": ("probe",),
}


class _PointRows:
    """Validates point rows one by one (from a CSV file or from ``[points] rows`` of a task) and
    collects them into a :class:`PointTable`.  ``where(column)`` names the place of a value."""

    def __init__(self, path: Path, probes: tuple[Probe, ...]):
        self.path = path
        self.probes = probes
        self.probe_ids = {p.id for p in probes}
        self.labels: list[str] = []
        self.X: list[list[float]] = []
        self.N: list[np.ndarray] = []
        self.pids: list[str] = []
        self.lines: list[int] = []
        self.seen: dict[str, str] = {}

    number_text = staticmethod(float)     # a CSV table's own reading of a number's text (decimal comma)

    def number(self, raw, where: str) -> float:
        if isinstance(raw, str):
            try:
                v = self.number_text(raw.strip())
            except ValueError:
                raise InputError(f"{raw.strip()!r} is not a number", file=self.path, where=where) from None
        elif isinstance(raw, bool) or not isinstance(raw, (int, float)):
            raise InputError(f"{raw!r} is not a number", file=self.path, where=where)
        else:
            v = float(raw)
        if not math.isfinite(v):
            raise InputError(f"{raw!r} is not a finite number", file=self.path, where=where)
        return v

    def add(self, line: int, origin: str, raw_label, raw_values: list, raw_probe, where) -> None:
        """One point: ``raw_values`` = x, y, z, nx, ny, nz; ``where(column)`` names each value."""
        if not isinstance(raw_label, str):
            raise InputError(f"{raw_label!r} is not text", file=self.path, where=where("id"))
        label = check_label(raw_label.strip(), self.path, where("id"))
        if label in self.seen:
            raise InputError(f"point id {label!r} also {self.seen[label]}", file=self.path, where=where("id"))
        self.seen[label] = origin
        vals = [self.number(v, where(c)) for v, c in zip(raw_values, ("x", "y", "z", "nx", "ny", "nz"))]
        for v, c in zip(vals[:3], "xyz"):
            problem = coordinate_problem(v)
            if problem is not None:
                raise InputError(problem, file=self.path, where=where(c))
        n = np.array(vals[3:])
        if abs(np.linalg.norm(n) - 1.0) > NORMAL_TOL:
            raise InputError(f"normal ({vals[3]:g}, {vals[4]:g}, {vals[5]:g}) is not a unit vector "
                             f"(length {np.linalg.norm(n):.6g})", file=self.path, where=where(None))
        if isinstance(raw_probe, str) and raw_probe.strip():
            pid = raw_probe.strip()
        elif raw_probe is None or isinstance(raw_probe, str):
            if len(self.probes) != 1:
                raise InputError("no probe given and the task has several", file=self.path,
                                 where=where("probe"))
            pid = self.probes[0].id
        else:
            raise InputError(f"{raw_probe!r} is not a probe id", file=self.path, where=where("probe"))
        if pid not in self.probe_ids:
            raise InputError(f"unknown probe {pid!r} (the task defines {', '.join(sorted(self.probe_ids))})",
                             file=self.path, where=where("probe"))
        self.labels.append(label)
        self.X.append(vals[:3])
        self.N.append(n / np.linalg.norm(n))
        self.pids.append(pid)
        self.lines.append(line)

    def table(self) -> PointTable:
        if not self.labels:
            raise InputError("no points", file=self.path)
        return PointTable(tuple(self.labels), np.array(self.X), np.array(self.N), tuple(self.pids),
                          tuple(self.lines))


def read_points_csv(path: Path, probes: tuple[Probe, ...]) -> PointTable:
    """``id,x,y,z,nx,ny,nz,probe`` (mm; n = outward unit normal).  Lines starting with ``#``
    before the header are comments.  ``probe`` may be omitted when the task has one probe.
    Comma-, semicolon- or tab-separated, header names in any letter case, decimal commas in
    semicolon/tab files, empty columns dropped (:mod:`xlfuncs.csvtable`); what was detected is
    noted (:func:`note`)."""
    path = Path(path)
    text = read_text(path, "points")
    known = [a for aliases in POINT_COLUMNS.values() for a in aliases]
    try:
        tbl = read_csv_table(text, known)
    except TableError as e:
        raise InputError(e.message, file=path, where=None if e.line is None else f"line {e.line}") from None
    header = list(tbl.header)
    start = tbl.header_line - 1
    colmap: dict[str, int] = {}
    for key, aliases in POINT_COLUMNS.items():
        given = [a for a in aliases if a in header]
        if len(given) > 1:
            raise InputError(f"columns {' and '.join(map(repr, given))} both give {key}: keep one",
                             file=path, where=f"line {start + 1}")
        if given:
            colmap[key] = header.index(given[0])
    for key in ("id", "x", "y", "z", "nx", "ny", "nz"):
        if key not in colmap:
            sep = tbl.delimiter if tbl.delimiter != "\t" else "\\t"
            raise InputError(f"missing column {POINT_COLUMNS[key][0]!r} (header: {sep.join(header)})",
                             file=path, where=f"line {start + 1}")
    points = _PointRows(path, probes)
    points.number_text = tbl.number
    try:
        for offset, row in tbl.records():

            def where(column, offset=offset):
                if column is None:
                    return f"line {offset}"
                name = header[colmap[column]] if column in colmap else column
                return f"line {offset}, column {name!r}"

            points.add(offset, f"on line {offset}", row[colmap["id"]],
                       [row[colmap[k]] for k in ("x", "y", "z", "nx", "ny", "nz")],
                       row[colmap["probe"]] if "probe" in colmap else None, where)
    except TableError as e:
        raise InputError(e.message, file=path, where=f"line {e.line}") from None
    for message in tbl.notes:
        note(message, file=path, where=f"line {tbl.header_line}")
    return points.table()


POINT_ROW_KEYS = {"id", "x", "y", "z", "x_mm", "y_mm", "z_mm", "nx", "ny", "nz", "probe"}


def read_points_rows(path: Path, rows, probes: tuple[Probe, ...]) -> PointTable:
    """Points written in the task file itself: ``[points] rows = [{id = "A", x_mm = 0, ...}, ...]``
    (keys as the CSV columns).  ``cmmwb read`` writes them so when a label starts with ``=``,
    ``+``, ``-`` or ``@``, which a spreadsheet program would take for a formula in a CSV file."""
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise InputError("must be a list of tables {id, x_mm, y_mm, z_mm, nx, ny, nz, probe}",
                         file=path, where="[points] rows")
    points = _PointRows(path, probes)
    for n, row in enumerate(rows, start=1):
        section = f"[points] rows #{n}"
        check_keys(path, row, section, POINT_ROW_KEYS)

        def where(column, section=section):
            return section if column is None else f"{section} key {column!r}"

        vals = []
        for key in ("x", "y", "z", "nx", "ny", "nz"):
            value = row.get(key, row.get(f"{key}_mm")) if key in "xyz" else row.get(key)
            if value is None:
                raise InputError("missing key", file=path, where=where(key))
            vals.append(value)
        if "id" not in row:
            raise InputError("missing key", file=path, where=where("id"))
        points.add(n, f"in {section}", row["id"], vals, row.get("probe"), where)
    return points.table()


def read_point_cloud(path: Path, doc: dict) -> tuple[PointCloud, Parameters, PointTable]:
    """The point-cloud model of a task: points (``[points] file`` or ``rows``), probes, parameters."""
    params = read_parameters(path, doc)
    probes = read_probes(path, doc)
    pts = table(path, doc, "points")
    check_keys(path, pts, "points", {"file", "rows"})
    if ("file" in pts) == ("rows" in pts):
        raise InputError("give either 'file' (a CSV of points) or 'rows' (points in the task file)",
                         file=path, where="[points]")
    if "rows" in pts:
        tablep = read_points_rows(path, pts["rows"], probes)
    else:
        name = string(path, pts, "points", "file")
        if "\x00" in name:
            raise InputError("the file name contains a NUL character", file=path, where="[points] file")
        if not name.strip():
            raise InputError("is empty: name the points table, a CSV file beside the task file "
                             "(or give the points as [points] rows)", file=path, where="[points] file")
        csv_path = Path(path).parent / name
        if csv_path.is_dir():
            raise InputError(f"{name!r} is a folder ({csv_path}), not a points table (CSV file)",
                             file=path, where="[points] file")
        tablep = read_points_csv(csv_path, probes)
    index = {p.id: k for k, p in enumerate(probes)}
    with model_errors_named(file=path, where="[[probes]]"):
        for p in probes:
            p.resolved(params)
        cloud = PointCloud(tablep.X_mm, tablep.N, np.array([index[p] for p in tablep.probe_ids]),
                           probes, tablep.labels)
    return cloud, params, tablep
