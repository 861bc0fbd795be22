"""The point-cloud model of a task file, shared by every kind that has one: ``[parameters]`` (the
six factors' hyper-parameters, Forbes 2025 Table 1), ``[[probes]]`` (id, offset_mm, per-probe
overrides) and ``[points]`` (a CSV table ``id,x,y,z,nx,ny,nz,probe`` beside the task file, or
``rows`` in the task itself), validated into :class:`xlfuncs.pointcloud.PointCloud`.

Every problem becomes one :class:`~generator.errors.InputError` naming the file and the key or
line (the getters of :mod:`generator.taskfile`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs.csvtable import TableError
from cmmwb.xlfuncs.csvtable import read_table as read_csv_table
from cmmwb.xlfuncs.limits import PLAUSIBLE, coordinate_problem, plausibility_problem
from cmmwb.xlfuncs.model.hyperparameters import PROBE_OVERRIDES, in_table, of_factor
from cmmwb.xlfuncs.pointcloud import Parameters, PointCloud, Probe

from .errors import InputError, model_errors_named
from .taskfile import Names, check_keys, note, number, string, table, vector3
from .taskworkpiece import apply_workpiece
from .workbook.guarded import MAX_BYTES, read_text

MAX_CSV_BYTES = MAX_BYTES["points"]
NORMAL_TOL = 1e-3


# -- the point-cloud model: [parameters], [[probes]], [points] --------------------------------

#: the hyper-parameters of [parameters], and those a [[probes]] entry may override (their records)
PARAMETER_KEYS = in_table("parameters")


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
        er = doc.get("parameters", {}).get(of_factor("ER")[0], 0) if isinstance(doc.get("parameters"), dict) else 0
        if isinstance(er, (int, float)) and not isinstance(er, bool) and er > 0:
            note(f"no [[probes]]: one probe P1 with offset [0, 0, 0] mm is assumed, {NO_OFFSET}", file=path,
                 where="[[probes]]")
        return (Probe("P1"),)
    if not isinstance(raw, list) or not raw or not all(isinstance(p, dict) for p in raw):
        raise InputError("must be one or more [[probes]] tables", file=path, where="[[probes]]")
    probes = []
    seen = Names(path, "probe id")
    for n, p in enumerate(raw, start=1):
        section = f"[[probes]] #{n}"
        check_keys(path, p, section, {"id", "offset_mm", *PROBE_OVERRIDES})
        pid = seen.add(check_label(string(path, p, section, "id").strip(), path, f"{section} id"), f"{section} id")
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


def points_source(doc: dict) -> str:
    """Where a task's points come from, in words for a report: ``the points table ([points]
    file)`` (its name and SHA-256 are in the report's header) or ``the points given in the task
    file ([points] rows)``.  The file is not named here, so that the words do not change when
    ``cmmwb read`` names the table after the task file."""
    pts = doc.get("points")
    name = pts.get("file") if isinstance(pts, dict) else None
    if isinstance(name, str):
        return "the points table ([points] file)"
    return "the points given in the task file ([points] rows)"


def read_point_cloud(path: Path, doc: dict) -> tuple[PointCloud, Parameters, PointTable]:
    """The point-cloud model of a task: points (``[points] file`` or ``rows``), probes, parameters,
    and the part's temperature (``[workpiece]``, the factor W: :mod:`generator.taskworkpiece`)."""
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
    cloud, params = apply_workpiece(path, doc, cloud, params)
    return cloud, params, tablep


@dataclass(frozen=True)
class MPE:
    """The MPE statement of a task's ``[mpe]`` (Forbes 2025 eq. (36)): E = A + L/B (µm, L in
    mm), coverage factor K, longest probe length P and the largest distance of the check."""

    A_um: float
    B_mm: float
    K: float
    P_mm: float
    L_max_mm: float


MPE_KEYS = {"A_um", "B_mm", "K", "P_mm", "L_max_mm"}
DEFAULT_L_MAX_MM = 1000.0


def read_mpe(path: Path, doc: dict, probes) -> MPE | None:
    """The task's ``[mpe]`` (None without one), the one reader of it (``build`` and ``calibrate``):
    unknown keys, a missing, non-finite, negative or zero A_um/B_mm/K are errors naming the key;
    P_mm defaults to the longest probe offset."""
    if "mpe" not in doc:
        return None
    t = table(path, doc, "mpe")
    check_keys(path, t, "mpe", MPE_KEYS)
    longest = max((math.sqrt(sum(v * v for v in p.offset_mm)) for p in probes), default=0.0)
    return MPE(number(path, t, "mpe", "A_um", positive=True), number(path, t, "mpe", "B_mm", positive=True),
               number(path, t, "mpe", "K", 2.0, positive=True), number(path, t, "mpe", "P_mm", longest, lo=0.0),
               number(path, t, "mpe", "L_max_mm", DEFAULT_L_MAX_MM, positive=True))
