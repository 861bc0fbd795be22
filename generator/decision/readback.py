"""The way back of the ``Decision`` sheet (``cmmwb read``): its inputs (r, max_pfa, k, each
tolerance's limits and measured value) into the task's ``[decision]`` table."""

from __future__ import annotations

from .decide import SECTION, tolerance_where

# -- the way back (`cmmwb read`) ---------------------------------------------------------------------

def read_back(cells, rt) -> None:
    """The Decision sheet's inputs back into ``rt.doc["decision"]`` (``cmmwb read``): r, max_pfa, k
    and each tolerance's limits and measured value, by their defined names.  A value still equal to
    the build-time one keeps the task file's form (``tol_mm`` around ``nominal_mm``); a changed limit
    turns the entry into ``lsl_mm``/``usl_mm``."""
    from openpyxl.utils import get_column_letter

    tbl = rt.doc.get(SECTION)
    # a characteristic task decided without [decision] (the default rule): a k typed in the sheet
    # makes the table
    created = tbl is None and "decision_k" in cells.wb.defined_names
    if created:
        tbl = {}
    if not isinstance(tbl, dict):
        return

    def value(name: str):
        ws, r, c = cells.named(name)
        x = cells.number(ws, r, c, name)
        built = cells.snapshot.get(f"{ws.title}!{get_column_letter(c)}{r}")
        return x, built, cells.where(ws, r, c)

    for key, name in (("r", "decision_r"), ("max_pfa", "decision_max_pfa"), ("k", "decision_k")):
        if name not in cells.wb.defined_names:
            continue
        x, built, where = value(name)
        if key in tbl or built is None or x != built:
            tbl[key] = x
        rt.sources[f"[{SECTION}] {key}"] = where
    if created and tbl:
        rt.doc[SECTION] = tbl
    entries = tbl.get("tolerances")
    if not isinstance(entries, list):
        return
    for n, t in enumerate(entries, start=1):
        if not isinstance(t, dict):
            continue
        got = {}
        for key in ("lsl_mm", "usl_mm", "measured_mm", "s_um", "n_repeats", "process_mean_mm", "process_sd_um"):
            name = f"tol{n}_{key}"
            if name in cells.wb.defined_names:
                got[key] = value(name)
                rt.sources[tolerance_where(n, key)] = got[key][2]
        for key in ("measured_mm", "s_um", "n_repeats", "process_mean_mm", "process_sd_um"):
            if key in got and got[key][0] != got[key][1]:
                t[key] = got[key][0]
        limits = {k_: v for k_, v in got.items() if k_ in ("lsl_mm", "usl_mm")}
        if any(x != built for x, built, _ in limits.values()):
            t.pop("tol_mm", None)
            t.pop("nominal_mm", None)
            for key, (x, _, where) in limits.items():
                t[key] = x
            rt.sources[tolerance_where(n, "tol_mm")] = next(iter(limits.values()))[2]
