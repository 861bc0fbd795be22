"""``cmmwb read`` of a ``budget`` workbook: the MPE (named cells), the part's temperature
(``[workpiece]``), the points table and the theoretical dimensions of position characteristics."""

from __future__ import annotations

from ..errors import InputError
from ..workbook.readback import MAX_TABLE_ROWS, Cells, ReadTask, Section
from ..workbook.tasksheet import TASK_SHEET
from ..workbook.workpiece import read_workpiece_cells


def read_budget(cells: Cells, rt: ReadTask) -> None:
    doc = rt.doc
    sec = Section(cells, rt, doc, "mpe")
    for key in ("A_um", "B_mm", "b", "k"):
        sec.scalar(key)
    read_workpiece_cells(cells, rt)          # [workpiece], when the task has it (the factor W)
    stored = doc.get("points")
    if not isinstance(stored, dict) or not stored:
        raise InputError("the task information has no points", file=cells.path, where=f"sheet {TASK_SHEET}")
    first = next(iter(stored))
    ws, r0, c0 = cells.named(f"{first}_x_mm")
    points: dict[str, list[float]] = {}
    r = r0
    while r < r0 + MAX_TABLE_ROWS:
        if all(cells.is_empty(ws, r, c) for c in range(c0, c0 + 3)):
            break   # the table ends at the first row without coordinates
        name = cells.label(ws, r, c0 - 1, "point name")
        if name is None:
            raise cells.error(ws, r, c0 - 1, "empty point name")
        if name in points:
            raise cells.error(ws, r, c0 - 1, f"point {name!r} is listed twice")
        points[name] = [cells.number(ws, r, c0 + a, f"{name}_{'xyz'[a]}_mm") for a in range(3)]
        rt.sources[f"[points] {name}"] = f"sheet {ws.title}, row {r}"
        r += 1
    doc["points"] = points
    chars = doc.get("characteristics")
    if isinstance(chars, list):
        for n, ch in enumerate(chars, start=1):
            if isinstance(ch, dict) and ch.get("model") == "position" and isinstance(ch.get("name"), str):
                teds = []
                for i in (1, 2):
                    ws, r, c = cells.named(f"{ch['name']}_ted{i}_mm")
                    teds.append(cells.number(ws, r, c, f"{ch['name']}_ted{i}_mm"))
                    rt.sources[f"[[characteristics]] #{n} key 'ted_mm'"] = Cells.where(ws, r, c)
                ch["ted_mm"] = teds
