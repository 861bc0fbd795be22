"""The results file of ``cmmwb validate`` (docs/validate.md, section 2): per measured
characteristic of a calibrated workpiece and run, the measured value (or its repeats, one row
each), the certificate's calibrated value, U_cal and k_cal; optionally the probed points of a
length (the columns of docs/recordings.md 1a), which hand the row to the mismatch locator.

Read with the one CSV parser (:mod:`cmmwb.xlfuncs.csvtable`: comma, semicolon or tab, decimal
commas, header names in any case), matched to the task's result records
(:class:`generator.quantities.Quantity`, by label) into the rows of
:class:`cmmwb.xlfuncs.validation.Rows`.  Every problem names the file, line and column.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs.csvtable import TableError, read_table
from cmmwb.xlfuncs.limits import coordinate_problem
from cmmwb.xlfuncs.validation import Geometry, Rows

from ..errors import InputError
from ..quantities import Quantity
from ..workbook.guarded import read_text

#: a characteristic's value unit -> the suffix of its measured_/calibrated_ columns
VALUE_SUFFIX = {"mm": "mm", "deg": "deg", "rad": "rad", "1": "1"}
#: its U unit -> the suffix of its U_cal_ column
U_SUFFIX = {"µm": "um", "µrad": "urad", "deg": "deg", "mm": "mm", "rad": "rad", "1": "1"}
GEOMETRY = ("x1", "y1", "z1", "x2", "y2", "z2")
NORMALS = ("n1x", "n1y", "n1z", "n2x", "n2y", "n2z")
OFFSETS = ("p1x", "p1y", "p1z", "p2x", "p2y", "p2z")
TEXT = ("characteristic", "workpiece", "run", "probe1", "probe2")
KNOWN = (set(TEXT) | {"k_cal"} | set(GEOMETRY) | set(NORMALS) | set(OFFSETS)
         | {f"{w}_{s}" for w in ("measured", "calibrated") for s in VALUE_SUFFIX.values()}
         | {f"U_cal_{s}" for s in U_SUFFIX.values()})
NORMAL_TOL = 1e-3


@dataclass
class ResultRow:
    line: int
    label: str
    workpiece: str
    run: str
    measured: float
    calibrated: float
    U_cal: float
    k_cal: float
    record: Quantity
    ends: tuple | None      # (X1, X2, N1, N2, P1, P2, probe1, probe2) or None


def normal_label(text: str) -> str:
    """A label as typed: ``A1->A2`` is the record's ``A1→A2``."""
    return text.strip().replace("->", "→")


def read_results(path: Path, records: dict[str, Quantity]) -> tuple[list[ResultRow], list[str]]:
    """The rows of the results file ``path``, each matched to its record of ``records`` (label ->
    record); and what the parser noticed (a semicolon-separated file, ...)."""
    text = read_text(path, "results")
    try:
        table = read_table(text, KNOWN)
    except TableError as e:
        raise InputError(e.message, file=path, where=_where(e.line, e.column)) from None
    col = {h: k for k, h in enumerate(table.header)}
    if "characteristic" not in col:
        raise InputError("missing column 'characteristic' (the label of the task's result: a point-cloud distance "
                         "FROM→TO or FROM->TO, a budget or drawing characteristic's name)", file=path,
                         where=f"line {table.header_line}")
    if "k_cal" not in col:
        raise InputError("missing column 'k_cal' (the certificate's coverage factor)", file=path,
                         where=f"line {table.header_line}")
    groups = {"x1..z2": GEOMETRY, "n1x..n2z": NORMALS, "p1x..p2z": OFFSETS, "probe1, probe2": ("probe1", "probe2")}
    present = {}
    for name, cols in groups.items():
        have = [c for c in cols if c in col]
        if have and len(have) != len(cols):
            miss = next(c for c in cols if c not in col)
            raise InputError(f"missing column {miss!r}: the columns {name} come together", file=path,
                             where=f"line {table.header_line}")
        present[name] = bool(have)
    if (present["n1x..n2z"] or present["p1x..p2z"] or present["probe1, probe2"]) and not present["x1..z2"]:
        raise InputError("normals, probe offsets or probe ids need the probed points x1..z2", file=path,
                         where=f"line {table.header_line}")
    out = []
    try:
        records_iter = list(table.records())
    except TableError as e:
        raise InputError(e.message, file=path, where=_where(e.line, e.column)) from None
    for line, fields in records_iter:
        def get(name: str) -> str:
            return fields[col[name]].strip() if name in col else ""

        def number(name: str, *, positive: bool = False, nonneg: bool = False) -> float:
            t = get(name)
            if not t:
                raise InputError(f"empty {name!r}: a number is needed here", file=path, where=_where(line, name))
            try:
                v = table.number(t)
            except ValueError:
                raise InputError(f"{t!r} is not a number", file=path, where=_where(line, name)) from None
            if not math.isfinite(v):
                raise InputError(f"{t!r} is not a finite number", file=path, where=_where(line, name))
            if positive and v <= 0:
                raise InputError(f"must be > 0, got {v:g}", file=path, where=_where(line, name))
            if nonneg and v < 0:
                raise InputError(f"must be >= 0, got {v:g}", file=path, where=_where(line, name))
            return v

        label = normal_label(get("characteristic"))
        if not label:
            raise InputError("empty characteristic", file=path, where=_where(line, "characteristic"))
        if label not in records:
            some = ", ".join(list(records)[:6]) + (", ..." if len(records) > 6 else "")
            raise InputError(f"no result {label!r} in the task (its results: {some})", file=path,
                             where=_where(line, "characteristic"))
        q = records[label]
        vs, us = VALUE_SUFFIX.get(q.unit), U_SUFFIX.get(q.U_unit)
        if vs is None or us is None:
            raise InputError(f"{label}: a result in {q.unit} with U in {q.U_unit} cannot be validated here",
                             file=path, where=_where(line, "characteristic"))
        for name in (f"measured_{vs}", f"calibrated_{vs}", f"U_cal_{us}"):
            if name not in col:
                raise InputError(f"{label} is in {q.unit} (U in {q.U_unit}): the file needs the column {name!r}",
                                 file=path, where=_where(line, "characteristic"))
        ends = None
        if present["x1..z2"] and any(get(c) for c in GEOMETRY + NORMALS + OFFSETS):
            X = np.array([number(c) for c in GEOMETRY])
            for c, v in zip(GEOMETRY, X):
                problem = coordinate_problem(v)
                if problem is not None:
                    raise InputError(problem, file=path, where=_where(line, c))
            if np.linalg.norm(X[3:] - X[:3]) <= 1e-9:
                raise InputError("the two probed points coincide", file=path, where=_where(line, "x2"))
            if q.unit != "mm":
                raise InputError(f"{label} is in {q.unit}: probed points x1..z2 belong to lengths (mm)", file=path,
                                 where=_where(line, "x1"))
            N = None
            if present["n1x..n2z"]:
                N = np.array([number(c) for c in NORMALS])
                for e, c in ((N[:3], "n1x"), (N[3:], "n2x")):
                    if abs(np.linalg.norm(e) - 1.0) > NORMAL_TOL:
                        raise InputError(f"normal ({e[0]:g}, {e[1]:g}, {e[2]:g}) is not a unit vector", file=path,
                                         where=_where(line, c))
            P = np.array([number(c) for c in OFFSETS]) if present["p1x..p2z"] else None
            ids = (get("probe1"), get("probe2")) if present["probe1, probe2"] else None
            if ids is not None and not all(ids):
                raise InputError("empty probe id", file=path, where=_where(line, "probe1" if not ids[0] else "probe2"))
            ends = (X[:3], X[3:], None if N is None else N[:3], None if N is None else N[3:],
                    None if P is None else P[:3], None if P is None else P[3:], ids)
        out.append(ResultRow(line, label, get("workpiece") or "workpiece", get("run") or "1",
                             number(f"measured_{vs}"), number(f"calibrated_{vs}"), number(f"U_cal_{us}", nonneg=True),
                             number("k_cal", positive=True), q, ends))
    if not out:
        raise InputError("no rows after the header", file=path, where=f"line {table.header_line}")
    return out, [f"line {table.header_line}: {n}" for n in table.notes]


def _where(line: int | None, column: str | None) -> str | None:
    parts = ([f"line {line}"] if line is not None else []) + ([f"column {column!r}"] if column else [])
    return ", ".join(parts) or None


def rows_and_geometry(path: Path, rows: list[ResultRow]) -> tuple[Rows, Geometry | None]:
    """The core's rows: repeats (rows of one characteristic, workpiece and run) averaged, with
    their number and standard deviation; the certificate (calibrated value, U_cal, k_cal) one per
    characteristic of a workpiece; the probed points of the length rows."""
    groups: dict[tuple[str, str, str], list[ResultRow]] = {}
    cert: dict[tuple[str, str], ResultRow] = {}
    for r in rows:
        groups.setdefault((r.workpiece, r.run, r.label), []).append(r)
        first = cert.setdefault((r.workpiece, r.label), r)
        for what, a, b in (("calibrated value", first.calibrated, r.calibrated), ("U_cal", first.U_cal, r.U_cal),
                           ("k_cal", first.k_cal, r.k_cal)):
            if a != b:
                raise InputError(f"{r.label} of {r.workpiece}: its {what} is {b:g} here but {a:g} on line "
                                 f"{first.line} (one certificate per characteristic of a workpiece)", file=path,
                                 where=f"line {r.line}")
        if (r.ends is None) != (first.ends is None):
            raise InputError(f"{r.label} of {r.workpiece}: probed points here but not on line {first.line} "
                             "(give them on every row or none)", file=path, where=f"line {r.line}")
    out: list[tuple[list[ResultRow], float, float]] = []
    for members in groups.values():
        r0 = members[0]
        scale = r0.record.unit_ratio
        vals = np.array([m.measured for m in members])
        s = float(np.std(vals, ddof=1) * scale) if len(vals) > 1 else math.nan
        for m in members[1:]:
            if (m.ends is None) != (r0.ends is None) or (m.ends is not None and any(
                    not _same(a, b) for a, b in zip(m.ends, r0.ends))):
                raise InputError(f"{m.label}: the repeats of one characteristic in one run (line {r0.line} and "
                                 "this one) have different probed points", file=path, where=f"line {m.line}")
        out.append((members, float(np.mean(vals)), s))
    geo_idx = [i for i, (m, _, _) in enumerate(out) if m[0].ends is not None]
    first = [m[0] for m, _, _ in out]
    core = Rows(tuple(r.label for r in first), tuple(r.workpiece for r in first), tuple(r.run for r in first),
                np.array([y for _, y, _ in out]), np.array([len(m) for m, _, _ in out]),
                np.array([s for _, _, s in out]), np.array([r.calibrated for r in first]),
                np.array([r.U_cal for r in first]), np.array([r.k_cal for r in first]),
                np.array([r.record.U for r in first]), np.array([r.record.k for r in first]),
                np.array([r.record.unit_ratio for r in first]), tuple(r.record.unit for r in first),
                tuple(r.record.U_unit for r in first), tuple(r.line for r in first))
    if not geo_idx:
        return core, None
    ends = [first[i].ends for i in geo_idx]

    def stack(k):
        return None if ends[0][k] is None else np.array([e[k] for e in ends])

    ids = ends[0][6]
    return core, Geometry(np.array(geo_idx), stack(0), stack(1), stack(2), stack(3), stack(4), stack(5),
                          None if ids is None else tuple(e[6][0] for e in ends),
                          None if ids is None else tuple(e[6][1] for e in ends))


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, tuple):
        return a == b
    return bool(np.max(np.abs(np.asarray(a) - np.asarray(b))) <= 1e-6)
