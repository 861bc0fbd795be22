"""``cmmwb read`` of a ``pointcloud`` workbook, and the point-cloud model both the point-cloud and
the feature workbooks carry: hyper-parameters (named cells on 'Inputs'), the probes table and the
'Points' table, which goes to a CSV file beside the task (or into the task file, see
:func:`use_points_file`).
"""

from __future__ import annotations

import csv
import io
import re
from typing import Any

from ..errors import InputError
from ..taskcloud import PARAMETER_KEYS, PROBE_OVERRIDES
from ..workbook.readback import CSV_HEADER, MAX_TABLE_ROWS, POINT_HEADER, Cells, ReadTask, Section
from ..workbook.workpiece import read_workpiece_cells


def read_parameters(cells: Cells, rt: ReadTask) -> None:
    """[parameters] and the part's [workpiece] (the factor W) from their named cells on 'Inputs'."""
    sec = Section(cells, rt, rt.doc, "parameters")
    for key in PARAMETER_KEYS:
        sec.scalar(key)
    read_workpiece_cells(cells, rt)


def read_probes(cells: Cells, rt: ReadTask) -> list[str]:
    """The probes table on 'Inputs', anchored at the cell named ``probe1_px_mm``."""
    ws, r0, c0 = cells.named("probe1_px_mm")
    probes = []
    ids: dict[str, int] = {}
    r = r0
    while r < r0 + MAX_TABLE_ROWS:
        if all(cells.is_empty(ws, r, c) for c in range(c0 - 1, c0 + 3 + len(PROBE_OVERRIDES))):
            break
        pid = cells.label(ws, r, c0 - 1, "probe id")
        if pid is None:
            raise cells.error(ws, r, c0 - 1, "empty probe id")
        if pid in ids:
            raise cells.error(ws, r, c0 - 1, f"probe id {pid!r} is also in row {ids[pid]}")
        ids[pid] = r
        p: dict[str, Any] = {"id": pid,
                             "offset_mm": [cells.number(ws, r, c0 + a, f"probe offset p{'xyz'[a]}_mm")
                                           for a in range(3)]}
        for k, key in enumerate(PROBE_OVERRIDES):
            col = c0 + 3 + k
            c = cells.raw(ws, r, col)
            if cells.is_formula(c) and re.fullmatch(rf"=\s*{key}\s*", cells.formula_text(c), re.I):
                continue   # the task-wide default
            v = cells.number(ws, r, col, f"{key} of probe {pid}", required=False)
            if v is not None:
                p[key] = v
        n = len(probes) + 1
        for key in (f"[[probes]] #{n}", f"[[[probes]] #{n}]"):
            rt.sources[key] = f"sheet {ws.title}, row {r}"
        probes.append(p)
        r += 1
    if not probes:
        raise cells.error(ws, r0, c0 - 1, "no probes in the probes table")
    rt.doc["probes"] = probes
    return list(ids)


def read_points_table(cells: Cells, probe_ids: list[str]) -> tuple[list[list], list[int]]:
    """The 'Points' table: rows of [id, x, y, z, nx, ny, nz, probe] and their sheet rows."""
    ws = cells.sheet("Points")
    header = [ws.cell(row=1, column=c).value for c in range(1, len(POINT_HEADER) + 1)]
    if header != POINT_HEADER:
        raise InputError(f"the header row must be {', '.join(POINT_HEADER)}; found "
                         f"{', '.join(str(h) for h in header)}", file=cells.path, where="sheet Points, row 1")
    rows, where = [], []
    seen: dict[str, int] = {}
    r = 2
    while r < 2 + MAX_TABLE_ROWS:
        if all(cells.is_empty(ws, r, c) for c in range(1, 9)):
            break
        label = cells.label(ws, r, 1, "point id")
        if label is None:
            raise cells.error(ws, r, 1, "empty point id")
        if label in seen:
            raise cells.error(ws, r, 1, f"point id {label!r} is also in row {seen[label]}")
        seen[label] = r
        names = ("x_mm", "y_mm", "z_mm", "nx", "ny", "nz")
        vals = [cells.number(ws, r, 2 + k, f"{names[k]} of point {label}") for k in range(6)]
        probe = cells.label(ws, r, 8, f"probe of point {label}")
        if probe is None and len(probe_ids) == 1:
            probe = probe_ids[0]
        if probe is None:
            raise cells.error(ws, r, 8, f"no probe given for point {label} and the task has several "
                              f"({', '.join(probe_ids)})")
        if probe not in probe_ids:
            raise cells.error(ws, r, 8, f"unknown probe {probe!r} (the probes table has "
                              f"{', '.join(probe_ids)})")
        rows.append([label, *vals, probe])
        where.append(r)
        r += 1
    if not rows:
        raise InputError("no points", file=cells.path, where="sheet Points, row 2")
    return rows, where


def _points_csv(rows: list[list]) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(CSV_HEADER)
    for row in rows:
        w.writerow([row[0], *(repr(float(v)) for v in row[1:7]), row[7]])
    return out.getvalue()


FORMULA_LIKE = ("=", "+", "-", "@")


def use_points_file(rt: ReadTask, rows: list[list], where: list[int], points_file: str) -> None:
    """Points go to a CSV file beside the task, unless a label starts with = + - @: a spreadsheet
    program opening that CSV would take it for a formula, so those points stay in the task file
    (``[points] rows``), where no program evaluates anything."""
    if any(str(row[0]).startswith(FORMULA_LIKE) or str(row[7]).startswith(FORMULA_LIKE) for row in rows):
        rt.doc["points"] = {"rows": [dict(zip(CSV_HEADER, [row[0], *(float(v) for v in row[1:7]), row[7]]))
                                     for row in rows]}
        for n, r in enumerate(where, start=1):
            rt.sources[f"[points] rows #{n}"] = f"sheet Points, row {r}"
    else:
        rt.files[points_file] = _points_csv(rows)
        rt.doc["points"] = {"file": points_file}
        rt.csv_rows = {line: f"sheet Points, row {r}" for line, r in enumerate(where, start=2)}
    rt.sources["[points]"] = "sheet Points"


def read_pointcloud(cells: Cells, rt: ReadTask, points_file: str) -> None:
    read_parameters(cells, rt)
    if "mpe" in rt.doc:
        sec = Section(cells, rt, rt.doc, "mpe")
        for key in ("A_um", "B_mm", "K", "P_mm", "L_max_mm"):
            sec.scalar(key)
    else:
        Section(cells, rt, rt.doc, "task").scalar("K")
    probe_ids = read_probes(cells, rt)
    rows, where = read_points_table(cells, probe_ids)
    use_points_file(rt, rows, where, points_file)
