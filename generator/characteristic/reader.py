"""``cmmwb read`` of a ``characteristic`` workbook: the point-cloud model (the 'Inputs' and
'Points' sheets, as the point-cloud workbook) and the tolerances typed on 'Characteristics'
(nominal, lsl, usl, tolerance_mm of each characteristic, by name); the features, frames and the
rest of each characteristic come from the task the workbook was built from."""

from __future__ import annotations

from ..pointcloud.reader import read_parameters, read_points_table, read_probes, use_points_file
from ..workbook.readback import MAX_TABLE_ROWS, Cells, ReadTask

#: 'Characteristics' columns the reader takes back (book.CHAR_COLUMNS positions, 1-based)
TOLERANCE_COLUMNS = {"nominal": 8, "lsl": 9, "usl": 10, "tolerance_mm": 11}


def read_characteristic(cells: Cells, rt: ReadTask, points_file: str) -> None:
    read_parameters(cells, rt)
    probe_ids = read_probes(cells, rt)
    rows, where = read_points_table(cells, probe_ids)
    use_points_file(rt, rows, where, points_file)
    chars = rt.doc.get("characteristics")
    if not isinstance(chars, list):
        return
    ws = cells.sheet("Characteristics")
    by_name = {}
    for r in range(2, 2 + MAX_TABLE_ROWS):
        name = cells.label(ws, r, 1, "characteristic")
        if name is None:
            break
        by_name[name] = r
    for n, c in enumerate(chars, start=1):
        if not isinstance(c, dict) or c.get("name") not in by_name:
            continue
        r = by_name[c["name"]]
        for key, col in TOLERANCE_COLUMNS.items():
            v = cells.number(ws, r, col, f"{key} of {c['name']}", required=False)
            if v is None:
                c.pop(key, None)
            else:
                c[key] = v
                rt.sources[f"[[characteristics]] #{n} {key}"] = f"sheet Characteristics, row {r}"
