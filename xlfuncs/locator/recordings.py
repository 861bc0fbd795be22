"""Recordings of a CMM (``docs/recordings.md`` section 1): reading, validating, writing.

Two kinds of file, told apart by the header:

* **length records** (header has ``measured_mm``): one measured length between two probed points
  per row, with its calibrated reference;
* **point records** (header has ``x_nom``): one measured point per row with its nominal
  coordinates (placement in the machine unknown: a rigid alignment is part of the baseline).

Units: coordinates, offsets and lengths in mm; temperatures in °C (reference 20 °C); times in s.
Normals are outward unit surface normals.  Numbers only (stdlib ``csv`` + numpy): the generator
wraps :class:`RecordingsError` into its ``InputError`` naming the file, line and column.
"""

from __future__ import annotations

import csv
import io
import math
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..csvtable import Table, TableError, read_table
from ..errors import ModelError
from ..limits import coordinate_problem

NORMAL_TOL = 1e-3           # spec section 1: a normal must be unit length within 1e-3
OFFSET_TOL_MM = 1e-6        # one probe id, one offset (within 1 nm)
MAX_BYTES = 256 * 1024 * 1024
T_REF_C = 20.0

LENGTH_REQUIRED = ("id", "x1", "y1", "z1", "x2", "y2", "z2", "reference_mm", "measured_mm")
POINT_REQUIRED = ("id", "x_nom", "y_nom", "z_nom", "x", "y", "z")
#: optional numeric column groups: all columns of a group or none
LENGTH_GROUPS = {
    "normals": ("n1x", "n1y", "n1z", "n2x", "n2y", "n2z"),
    "offsets": ("p1x", "p1y", "p1z", "p2x", "p2y", "p2z"),
}
POINT_GROUPS = {"normals": ("nx", "ny", "nz"), "offsets": ("px", "py", "pz")}
KNOWN_LENGTH = set(LENGTH_REQUIRED) | {c for g in LENGTH_GROUPS.values() for c in g} | {
    "probe1", "probe2", "temperature_C", "time_s", "group"}
KNOWN_POINT = set(POINT_REQUIRED) | {c for g in POINT_GROUPS.values() for c in g} | {
    "probe", "temperature_C", "time_s", "group"}


class RecordingsError(ModelError):
    """Bad recordings: ``line`` (1-based line of the file) and ``column`` (header name) say where."""

    def __init__(self, message: str, line: int | None = None, column: str | None = None):
        super().__init__(message)
        self.message = message
        self.line = line
        self.column = column

    @property
    def where(self) -> str | None:
        parts = []
        if self.line is not None:
            parts.append(f"line {self.line}")
        if self.column is not None:
            parts.append(f"column {self.column!r}")
        return ", ".join(parts) or None

    def __str__(self) -> str:
        w = self.where
        return f"{w}: {self.message}" if w else self.message


@dataclass
class Recordings:
    """Fields common to both kinds.  Optional columns are ``None`` when absent from the file."""

    kind: str                                  # "length" | "point"
    ids: tuple[str, ...]
    lines: tuple[int, ...]                     # line of each record in the file
    temperature_C: np.ndarray | None = None
    time_s: np.ndarray | None = None
    group: tuple[str, ...] | None = None
    extra: dict[str, list[str]] = field(default_factory=dict)   # unknown columns, kept as text
    comments: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()                # what was detected in the file (xlfuncs.csvtable)

    @property
    def n(self) -> int:
        return len(self.ids)


@dataclass
class LengthRecords(Recordings):
    X1_mm: np.ndarray = None                   # (n, 3)
    X2_mm: np.ndarray = None
    reference_mm: np.ndarray = None            # (n,)
    measured_mm: np.ndarray = None
    N1: np.ndarray | None = None               # (n, 3) outward normals
    N2: np.ndarray | None = None
    P1_mm: np.ndarray | None = None            # (n, 3) probe offsets
    P2_mm: np.ndarray | None = None
    probe1: tuple[str, ...] | None = None
    probe2: tuple[str, ...] | None = None

    @property
    def residual_um(self) -> np.ndarray:
        """measured - reference in µm (the simulation predicts zero)."""
        return (self.measured_mm - self.reference_mm) * 1000.0


@dataclass
class PointRecords(Recordings):
    X_nom_mm: np.ndarray = None                # (n, 3)
    X_mm: np.ndarray = None                    # (n, 3) measured
    N: np.ndarray | None = None
    P_mm: np.ndarray | None = None
    probe: tuple[str, ...] | None = None

    @property
    def planar(self) -> bool:
        """2-D data (spec section 6): z_nom and z each constant."""
        return bool(np.ptp(self.X_nom_mm[:, 2]) == 0.0 and np.ptp(self.X_mm[:, 2]) == 0.0)


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------

#: columns holding coordinates or lengths in mm: within the plausible machine range
#: (:data:`xlfuncs.limits.MAX_COORDINATE_MM`), where float64 keeps 1 nm
COORDINATE_COLUMNS = frozenset({"x1", "y1", "z1", "x2", "y2", "z2", "x_nom", "y_nom", "z_nom", "x", "y", "z",
                                "reference_mm", "measured_mm", "p1x", "p1y", "p1z", "p2x", "p2y", "p2z",
                                "px", "py", "pz"})


def _number(text: str, line: int, column: str, table: Table | None = None) -> float:
    t = text.strip()
    try:
        v = table.number(t) if table is not None else float(t)
    except ValueError:
        raise RecordingsError(f"{t!r} is not a number", line, column) from None
    if not math.isfinite(v):
        raise RecordingsError(f"{t!r} is not a finite number", line, column)
    return v


def read_recordings(path: str | Path) -> LengthRecords | PointRecords:
    """Read and validate a recordings CSV (spec section 1); raises :class:`RecordingsError`."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)   # a FIFO must not block the open
        with os.fdopen(fd, "rb") as fh:
            st = os.fstat(fh.fileno())
            if not stat.S_ISREG(st.st_mode):
                raise RecordingsError("not a regular file (a FIFO, a device or a folder): refused")
            if st.st_size > MAX_BYTES:
                raise RecordingsError(f"larger than {MAX_BYTES // 2**20} MiB")
            os.set_blocking(fd, True)
            raw = fh.read(MAX_BYTES + 1)
        if len(raw) > MAX_BYTES:
            raise RecordingsError(f"larger than {MAX_BYTES // 2**20} MiB")
    except OSError as e:
        raise RecordingsError(f"cannot read the recordings: {e.strerror}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise RecordingsError(f"not UTF-8 text (byte {e.start})") from None
    return parse_recordings(text)


def parse_recordings(text: str) -> LengthRecords | PointRecords:
    """Recordings from the file's text: comma-, semicolon- or tab-separated, header names in any
    letter case, decimal commas in semicolon/tab files, empty columns dropped
    (:mod:`xlfuncs.csvtable`, the parser of the points tables too)."""
    try:
        table = read_table(text, KNOWN_LENGTH | KNOWN_POINT)
    except TableError as e:
        raise RecordingsError(e.message, e.line, e.column) from None
    comments = list(table.comments)
    header_line = table.header_line
    header = list(table.header)
    seen = {h: k for k, h in enumerate(header)}
    if "measured_mm" in seen and "x_nom" in seen:
        raise RecordingsError("the header has both measured_mm (length records) and x_nom (point "
                              "records); one file holds one kind", header_line)
    if "measured_mm" in seen:
        kind, required, groups, known = "length", LENGTH_REQUIRED, LENGTH_GROUPS, KNOWN_LENGTH
    elif "x_nom" in seen:
        kind, required, groups, known = "point", POINT_REQUIRED, POINT_GROUPS, KNOWN_POINT
    else:
        raise RecordingsError("the header has neither measured_mm (length records) nor x_nom (point "
                              f"records) (header: {','.join(header)})", header_line)
    for c in required:
        if c not in seen:
            raise RecordingsError(f"missing column {c!r} ({kind} records need "
                                  f"{','.join(required)})", header_line)
    present = {}
    for gname, cols in groups.items():
        have = [c for c in cols if c in seen]
        if have and len(have) != len(cols):
            miss = next(c for c in cols if c not in seen)
            raise RecordingsError(f"missing column {miss!r}: {gname} need all of {','.join(cols)}",
                                  header_line)
        present[gname] = bool(have)

    numeric = list(required[1:]) + [c for g, cols in groups.items() if present[g] for c in cols]
    for c in ("temperature_C", "time_s"):
        if c in seen:
            numeric.append(c)
    labels = [c for c in (("probe1", "probe2") if kind == "length" else ("probe",)) if c in seen]
    if kind == "length" and len(labels) == 1:
        raise RecordingsError(f"missing column {'probe2' if labels == ['probe1'] else 'probe1'!r}: "
                              "probe ids need probe1 and probe2", header_line)
    extra_cols = [h for h in header if h not in known]

    values: dict[str, list[float]] = {c: [] for c in numeric}
    text_cols: dict[str, list[str]] = {c: [] for c in labels + (["group"] if "group" in seen else [])}
    extra: dict[str, list[str]] = {c: [] for c in extra_cols}
    ids: list[str] = []
    where: list[int] = []
    id_line: dict[str, int] = {}
    try:
        records = list(table.records())
    except TableError as e:
        raise RecordingsError(e.message, e.line, e.column) from None
    for offset, row in records:
        rid = row[seen["id"]].strip()
        if not rid:
            raise RecordingsError("empty record id", offset, "id")
        if rid in id_line:
            raise RecordingsError(f"record id {rid!r} also on line {id_line[rid]}", offset, "id")
        id_line[rid] = offset
        ids.append(rid)
        where.append(offset)
        for c in numeric:
            values[c].append(_number(row[seen[c]], offset, c, table))
            if c in COORDINATE_COLUMNS:
                problem = coordinate_problem(values[c][-1])
                if problem is not None:
                    raise RecordingsError(problem, offset, c)
        for c in text_cols:
            v = row[seen[c]].strip()
            if c != "group" and not v:
                raise RecordingsError("empty probe id", offset, c)
            text_cols[c].append(v)
        for c in extra_cols:
            extra[c].append(row[seen[c]])
    if not ids:
        raise RecordingsError("no records after the header", header_line)

    arr = {c: np.array(v, dtype=float) for c, v in values.items()}
    common = dict(ids=tuple(ids), lines=tuple(where), extra=extra, comments=tuple(comments),
                  notes=tuple(f"line {header_line}: {n}" for n in table.notes),
                  temperature_C=arr.get("temperature_C"), time_s=arr.get("time_s"),
                  group=tuple(text_cols["group"]) if "group" in text_cols else None)

    def stack(cols: Sequence[str]) -> np.ndarray:
        return np.column_stack([arr[c] for c in cols])

    def check_normals(N: np.ndarray, cols: Sequence[str]) -> None:
        norm = np.linalg.norm(N, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > NORMAL_TOL)
        if bad.size:
            i = bad[0]
            raise RecordingsError(f"normal ({N[i, 0]:g}, {N[i, 1]:g}, {N[i, 2]:g}) is not a unit vector "
                                  f"(length {norm[i]:.6g}; tolerance {NORMAL_TOL:g})", where[i], cols[0])

    if kind == "length":
        rec = LengthRecords(kind="length", **common,
                            X1_mm=stack(("x1", "y1", "z1")), X2_mm=stack(("x2", "y2", "z2")),
                            reference_mm=arr["reference_mm"], measured_mm=arr["measured_mm"])
        if present["normals"]:
            rec.N1, rec.N2 = stack(("n1x", "n1y", "n1z")), stack(("n2x", "n2y", "n2z"))
            check_normals(rec.N1, ("n1x",))
            check_normals(rec.N2, ("n2x",))
            rec.N1 = rec.N1 / np.linalg.norm(rec.N1, axis=1)[:, None]
            rec.N2 = rec.N2 / np.linalg.norm(rec.N2, axis=1)[:, None]
        if present["offsets"]:
            rec.P1_mm, rec.P2_mm = stack(("p1x", "p1y", "p1z")), stack(("p2x", "p2y", "p2z"))
        if labels:
            rec.probe1, rec.probe2 = tuple(text_cols["probe1"]), tuple(text_cols["probe2"])
        d = np.linalg.norm(rec.X2_mm - rec.X1_mm, axis=1)
        bad = np.flatnonzero(d <= 1e-9)
        if bad.size:
            raise RecordingsError("the two probed points coincide: the direction of the length is "
                                  "undefined", where[bad[0]], "x2")
        bad = np.flatnonzero(rec.reference_mm <= 0)
        if bad.size:
            raise RecordingsError(f"reference length must be positive, got {rec.reference_mm[bad[0]]:g}",
                                  where[bad[0]], "reference_mm")
        if rec.n < 2:
            raise RecordingsError("one length record only: the chi-square test needs 2 records at least "
                                  "(fewer records than parameters)", where[0])
    else:
        rec = PointRecords(kind="point", **common, X_nom_mm=stack(("x_nom", "y_nom", "z_nom")),
                           X_mm=stack(("x", "y", "z")))
        if present["normals"]:
            rec.N = stack(("nx", "ny", "nz"))
            check_normals(rec.N, ("nx",))
            rec.N = rec.N / np.linalg.norm(rec.N, axis=1)[:, None]
        if present["offsets"]:
            rec.P_mm = stack(("px", "py", "pz"))
        if labels:
            rec.probe = tuple(text_cols["probe"])
        dims = 2 if rec.planar else 3
        n_align = 3 if dims == 2 else 6
        if dims * rec.n <= n_align:
            raise RecordingsError(
                f"{rec.n} point records give {dims * rec.n} coordinates, not more than the {n_align} "
                f"parameters of the rigid alignment (fewer records than parameters)", where[-1])
    _check_probe_offsets(rec)
    return rec


def _check_probe_offsets(rec: Recordings) -> None:
    """One probe id, one offset (records with equal ids share a probe, spec section 1)."""
    if isinstance(rec, LengthRecords):
        if rec.probe1 is None or rec.P1_mm is None:
            return
        ends = [(rec.probe1, rec.P1_mm, "p1x"), (rec.probe2, rec.P2_mm, "p2x")]
    else:
        if rec.probe is None or rec.P_mm is None:
            return
        ends = [(rec.probe, rec.P_mm, "px")]
    first: dict[str, tuple[np.ndarray, int]] = {}
    for a in range(rec.n):
        for ids, P, col in ends:
            pid = ids[a]
            if pid in first:
                p0, line0 = first[pid]
                if np.max(np.abs(P[a] - p0)) > OFFSET_TOL_MM:
                    raise RecordingsError(
                        f"probe {pid!r} has offset ({P[a, 0]:g}, {P[a, 1]:g}, {P[a, 2]:g}) here but "
                        f"({p0[0]:g}, {p0[1]:g}, {p0[2]:g}) on line {line0}: one probe id, one offset",
                        rec.lines[a], col)
            else:
                first[pid] = (P[a].copy(), rec.lines[a])


# ---------------------------------------------------------------------------------------------
# writing (the simulator's output; the same format the reader accepts)
# ---------------------------------------------------------------------------------------------

def _fmt(v: float, decimals: int) -> str:
    s = f"{v:.{decimals}f}"
    if s.startswith("-") and float(s) == 0.0:
        s = s[1:]
    return s


def write_recordings(rec: LengthRecords | PointRecords, path: str | Path | None = None,
                     comments: Sequence[str] = ()) -> str:
    """CSV text of ``rec`` (written to ``path`` when given).  Coordinates with 1 nm resolution,
    measured lengths with 0.1 nm, normals with 1e-9."""
    out = io.StringIO()
    for c in comments:
        out.write(f"# {c}\n")
    w = csv.writer(out, lineterminator="\n")
    cols: list[tuple[str, list[str]]] = [("id", list(rec.ids))]

    def num(name: str, v: np.ndarray, dec: int) -> None:
        cols.append((name, [_fmt(x, dec) for x in v]))

    if isinstance(rec, LengthRecords):
        for e, X in (("1", rec.X1_mm), ("2", rec.X2_mm)):
            for a, ax in enumerate("xyz"):
                num(f"{ax}{e}", X[:, a], 6)
        num("reference_mm", rec.reference_mm, 7)
        num("measured_mm", rec.measured_mm, 7)
        if rec.N1 is not None:
            for e, N in (("1", rec.N1), ("2", rec.N2)):
                for a, ax in enumerate("xyz"):
                    num(f"n{e}{ax}", N[:, a], 9)
        if rec.P1_mm is not None:
            for e, P in (("1", rec.P1_mm), ("2", rec.P2_mm)):
                for a, ax in enumerate("xyz"):
                    num(f"p{e}{ax}", P[:, a], 6)
        if rec.probe1 is not None:
            cols += [("probe1", list(rec.probe1)), ("probe2", list(rec.probe2))]
    else:
        for a, ax in enumerate("xyz"):
            num(f"{ax}_nom", rec.X_nom_mm[:, a], 6)
        for a, ax in enumerate("xyz"):
            num(ax, rec.X_mm[:, a], 6)
        if rec.N is not None:
            for a, ax in enumerate("xyz"):
                num(f"n{ax}", rec.N[:, a], 9)
        if rec.P_mm is not None:
            for a, ax in enumerate("xyz"):
                num(f"p{ax}", rec.P_mm[:, a], 6)
        if rec.probe is not None:
            cols.append(("probe", list(rec.probe)))
    if rec.temperature_C is not None:
        num("temperature_C", rec.temperature_C, 4)
    if rec.time_s is not None:
        num("time_s", rec.time_s, 2)
    if rec.group is not None:
        cols.append(("group", list(rec.group)))
    for name, vals in rec.extra.items():
        cols.append((name, list(vals)))
    w.writerow([c for c, _ in cols])
    for a in range(rec.n):
        w.writerow([v[a] for _, v in cols])
    text = out.getvalue()
    if path is not None:
        Path(path).write_text(text, encoding="utf-8")
    return text
