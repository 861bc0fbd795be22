"""``cmmwb read`` of a ``feature`` workbook: the point-cloud model (as the point-cloud workbook),
the weights on 'Local' and the planning values on 'Planning'."""

from __future__ import annotations

from openpyxl.utils import get_column_letter

from ..errors import InputError
from ..pointcloud.reader import read_parameters, read_points_table, read_probes, use_points_file
from ..workbook.readback import MAX_TABLE_ROWS, Cells, ReadTask


def read_feature(cells: Cells, rt: ReadTask, points_file: str) -> None:
    doc = rt.doc
    read_parameters(cells, rt)
    probe_ids = read_probes(cells, rt)
    rows, where = read_points_table(cells, probe_ids)
    built_rows = sum(1 for k in cells.snapshot if k.startswith("Points!B"))
    unchanged = len(rows) == built_rows and all(
        cells.snapshot.get(f"Points!{get_column_letter(2 + k)}{r}") == row[1 + k]
        for row, r in zip(rows, where) for k in range(6))
    sampling = doc.get("sampling")
    if isinstance(sampling, dict) and unchanged and [row[7] for row in rows] == [
            sampling.get("probe", probe_ids[0])] * len(rows):
        pass  # the sampled points as built: keep the strategy
    else:
        if isinstance(sampling, dict):
            doc.pop("sampling")
            if isinstance(doc.get("planning"), dict):
                doc["planning"].setdefault("pattern", sampling.get("pattern"))
        use_points_file(rt, rows, where, points_file)
    _read_weights(cells, rt, [row[0] for row in rows])
    if isinstance(doc.get("planning"), dict):
        _read_planning(cells, rt, built_rows)


def _read_weights(cells: Cells, rt: ReadTask, labels: list[str]) -> None:
    """Weights w_i (Forbes 2022 eq. (11)) from column 'w' of the 'Local' sheet, by point id."""
    ws = cells.sheet("Local")
    if [ws.cell(row=1, column=c).value for c in (1, 2)] != ["id", "w"]:
        raise InputError("the header row must start with id, w", file=cells.path, where="sheet Local, row 1")
    wanted = set(labels)
    weights: dict[str, float] = {}
    r = 2
    while r < 2 + MAX_TABLE_ROWS and not (cells.is_empty(ws, r, 1) and cells.is_empty(ws, r, 2)):
        label = cells.label(ws, r, 1, "point id")
        w = cells.number(ws, r, 2, f"weight of point {label}")
        if w < 0:
            raise cells.error(ws, r, 2, f"{w:g} is not allowed here (a weight w is >= 0)")
        if label in wanted and w != 1.0:
            weights[label] = w
        rt.sources[f"[feature] weights.{label}"] = Cells.where(ws, r, 2)
        r += 1
    feature = rt.doc.setdefault("feature", {})
    if weights:
        feature["weights"] = weights
    else:
        feature.pop("weights", None)


def _read_planning(cells: Cells, rt: ReadTask, built_points: int) -> None:
    """Planning geometry and m_points (named cells on 'Planning') and the sweep values."""
    plan = rt.doc["planning"]
    ws = cells.sheet("Planning")
    named: dict[str, float] = {}
    for name, dn in cells.wb.defined_names.items():
        try:
            dests = list(dn.destinations)
        except Exception:
            continue
        # geometry keys and m_points; not the names of input tables (Planning_<column>)
        if len(dests) == 1 and dests[0][0] == "Planning" and ":" not in dests[0][1] and \
                not name.startswith("Planning_"):
            wsn, r, c = cells.named(name)
            named[name] = cells.number(wsn, r, c, name)
            rt.sources[f"[planning] {name}"] = Cells.where(wsn, r, c)
    pairs = {"theta_deg": ("theta_from_deg", "theta_to_deg"), "phi_range_deg": ("phi_from_deg", "phi_to_deg")}
    for key, (a, b) in pairs.items():
        if a in named and b in named:
            plan[key] = [named.pop(a), named.pop(b)]
    if "m_points" in named:
        m = named.pop("m_points")
        ws_m, r, c = cells.named("m_points")
        if not m.is_integer() or m < 1:
            raise cells.error(ws_m, r, c, f"{m:g}: m_points is a whole number >= 1")
        if "m_points" in plan or int(m) != built_points:
            plan["m_points"] = int(m)
    plan.update(named)
    sweep = plan.get("sweep")
    if isinstance(sweep, str):
        top = None
        for r in range(1, min(ws.max_row, 200) + 1):
            b = ws.cell(row=r, column=2).value
            if ws.cell(row=r, column=1).value == sweep and isinstance(b, str) and b.startswith("s("):
                top = r
                break
        if top is None:
            raise InputError(f"no table with the sweep values {sweep!r}", file=cells.path, where="sheet Planning")
        values = []
        r = top + 1
        while r < top + 1 + MAX_TABLE_ROWS and not cells.is_empty(ws, r, 1):
            values.append(cells.number(ws, r, 1, f"{sweep} (planning sweep)"))
            r += 1
        plan["values"] = values
        rt.sources["[planning] values"] = f"sheet Planning, cells A{top + 1}:A{r - 1}"
