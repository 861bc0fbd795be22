"""The part's temperature on a workbook's inputs sheet (the factor W, docs/workpiece.md): its named
inputs (``workpiece_<key>``: the task's ``[workpiece]`` keys) and the two live formulas every other
sheet reads, ``workpiece_bias_ppm`` (the expansion the CMM leaves uncorrected) and
``workpiece_u_eps_ppm`` (u(eps): a length L gets u_W = L u(eps) x 10^-3 µm).  Written by every kind
(``pointcloud``, ``feature``, ``characteristic`` through ``generator.pointcloud.vx_sheets``; ``budget``
on its Inputs sheet), read back by ``read_workpiece_cells``.  Without a ``[workpiece]`` table the
inputs are there with ``workpiece_enabled`` = 0: switching W on is typing 1 and the part's values."""

from __future__ import annotations

from cmmwb.xlfuncs.model.hyperparameters import HYPER, in_table
from cmmwb.xlfuncs.model.workpiece import PREFIX, REFERENCE_C, STATE_CELLS, Workpiece, state_cells

from .book import Book

#: the values of the inputs of a task without [workpiece] (W off; steel at 20 °C)
OFF = Workpiece(alpha_ppm_per_K=11.5, T_degC=REFERENCE_C, enabled=False)
U_EPS = PREFIX + "u_eps_ppm"
BIAS = PREFIX + "bias_ppm"

_NOTES = {
    "enabled": "1: the factor W (the part's thermal expansion) on; 0: off",
    "alpha_ppm_per_K": "alpha of the part: aluminium 23.1, steel 11.5 (Swyt 1994)",
    "T_degC": "T, the part's mean temperature during the measurement",
    "dT_K": "temperature difference across the part: u = dT/sqrt(12)",
    "corrected": "1: the CMM corrects to 20 °C with alpha_corr; 0: no correction",
    "alpha_corr_ppm_per_K": "the alpha the CMM corrects with (default: the part's)",
    "fixture_x_mm": "x0: the point the part expands about (where it is held)",
    "fixture_y_mm": "y0 of the fixture point",
    "fixture_z_mm": "z0 of the fixture point",
}
_UNITS = {"enabled": "1/0", "alpha_ppm_per_K": "ppm/K", "T_degC": "°C", "dT_K": "K", "corrected": "1/0",
          "alpha_corr_ppm_per_K": "ppm/K", "fixture_x_mm": "mm", "fixture_y_mm": "mm", "fixture_z_mm": "mm"}
#: the order of the rows: the state, with u(alpha) after alpha and u(T) after T
ROWS = ("enabled", "alpha_ppm_per_K", "u_alpha_ppm_per_K", "T_degC", "u_T_K", "dT_K", "corrected",
        "alpha_corr_ppm_per_K", "fixture_x_mm", "fixture_y_mm", "fixture_z_mm")
assert set(ROWS) == set(STATE_CELLS) | set(in_table("workpiece"))
#: the rows :func:`write_workpiece_inputs` writes: the inputs, then the bias and u(eps)
N_ROWS = len(ROWS) + 2


def u_eps_formula() -> str:
    """u(eps) (10^-6) of the named inputs: (T - 20)^2 u^2(alpha) + alpha^2 (u^2(T) + dT^2/12) + b^2."""
    p = PREFIX
    return (f"={p}enabled*SQRT((({p}T_degC-{REFERENCE_C:g})*{p}u_alpha_ppm_per_K)^2"
            f"+{p}alpha_ppm_per_K^2*({p}u_T_K^2+{p}dT_K^2/12)+{BIAS}^2)")


def bias_formula() -> str:
    """b = (alpha - alpha_c)(T - 20), alpha_c = alpha_corr when the CMM corrects, else 0."""
    p = PREFIX
    return (f"=({p}alpha_ppm_per_K-IF({p}corrected=1,{p}alpha_corr_ppm_per_K,0))"
            f"*({p}T_degC-{REFERENCE_C:g})")


def write_workpiece_inputs(book: Book, ws, row: int, wp: Workpiece | None, u: dict[str, float],
                           *, columns: tuple[int, int, int, int] = (1, 2, 3, 4)) -> int:
    """The inputs of the part (rows from ``row``: name, value, unit, meaning in ``columns``) and the
    two formulas; returns the next free row.  ``wp`` None: the inputs of :data:`OFF`, W off."""
    cn, cv, cu, cm = columns
    state = state_cells(wp if wp is not None else OFF)
    inherit_alpha = wp is None or wp.alpha_corr_ppm_per_K is None
    r = row
    for key in ROWS:
        name = PREFIX + key
        book.text(ws, r, cn, name)
        if key in u or key in HYPER:
            note = HYPER[key].note
            book.input(ws, r, cv, name, float(u.get(key, 0.0)), lo=0.0, note=note)
            book.text(ws, r, cu, HYPER[key].unit)
        else:
            note = _NOTES[key]
            if key == "alpha_corr_ppm_per_K" and inherit_alpha:
                book.default(ws, r, cv, name, f"={PREFIX}alpha_ppm_per_K", note=note)
            else:
                flag = key in ("enabled", "corrected")
                book.input(ws, r, cv, name, state[key], lo=0.0 if (flag or key == "dT_K") else None,
                           hi=1.0 if flag else None, note=note)
            book.text(ws, r, cu, _UNITS[key])
        book.text(ws, r, cm, note)
        r += 1
    for name, formula, unit, meaning, note in (
            (BIAS, bias_formula(), "ppm", "b = (alpha - alpha_c)(T - 20): left uncorrected",
             "b = (alpha - alpha_c)(T - 20): the expansion the CMM leaves uncorrected (alpha_c = alpha_corr when "
             "it corrects, 0 when not); carried in u(eps) in quadrature (RSSu, docs/workpiece.md)"),
            (U_EPS, u_eps_formula(), "ppm", "u(eps): a length L gets u_W = L u(eps)",
             "u(eps) = sqrt((T - 20)^2 u^2(alpha) + alpha^2 (u^2(T) + dT^2/12) + b^2) when W is on: a length L "
             "gets u_W = L u(eps) x 0.001 µm/(ppm mm) (docs/workpiece.md)")):
        book.text(ws, r, cn, name)
        book.formula(ws, r, cv, formula, name=name, fmt="0.0000", note=note)
        book.text(ws, r, cu, unit)
        book.text(ws, r, cm, meaning)
        r += 1
    return r


# -- the way back (cmmwb read) ------------------------------------------------------------------------

def read_workpiece_cells(cells, rt) -> None:
    """``[workpiece]`` of the task read back from the workbook's named inputs (``cmmwb read``): a key
    the task had is written with the cell's value, a key it did not have only when its cell differs
    from the build-time value (so build -> read -> build is the identity: a task without the table
    gets none while the inputs stay as built).  ``material`` and ``T_readings_degC`` stay while alpha
    and T are unchanged; ``alpha_corr_ppm_per_K`` inheriting alpha by formula stays out.
    ``cells``: :class:`generator.workbook.readback.Cells`, ``rt``: its ``ReadTask``."""
    import re

    from openpyxl.utils import get_column_letter

    if cells.wb.defined_names.get(PREFIX + "alpha_ppm_per_K") is None:
        return                                   # a workbook written before the factor W
    had = isinstance(rt.doc.get("workpiece"), dict)
    tbl = dict(rt.doc["workpiece"]) if had else {}
    changed = False

    def value(key: str):
        nonlocal changed
        ws, r, c = cells.named(PREFIX + key)
        x = cells.number(ws, r, c, PREFIX + key)
        built = cells.snapshot.get(f"{ws.title}!{get_column_letter(c)}{r}")
        rt.sources[f"[workpiece] {key}"] = cells.where(ws, r, c)
        differs = built is None or x != built
        changed |= differs
        return x, differs

    for key in ("enabled", "corrected"):
        x, differs = value(key)
        if x not in (0.0, 1.0):
            ws, r, c = cells.named(PREFIX + key)
            raise cells.error(ws, r, c, f"{PREFIX}{key} must be 1 (yes) or 0 (no), got {x:g}")
        if key in tbl or differs:
            tbl[key] = bool(x)
    for key in ("alpha_ppm_per_K", "T_degC"):
        x, differs = value(key)
        keep = "material" if key == "alpha_ppm_per_K" else "T_readings_degC"
        if differs or keep not in tbl:
            tbl.pop(keep, None)
            tbl[key] = x
    for key in ("u_alpha_ppm_per_K", "u_T_K", "dT_K"):
        x, differs = value(key)
        if key in tbl or differs or key != "dT_K":
            tbl[key] = x
    ws, r, c = cells.named(PREFIX + "alpha_corr_ppm_per_K")
    raw = cells.raw(ws, r, c)
    if not (cells.is_formula(raw) and re.fullmatch(rf"=\s*{PREFIX}alpha_ppm_per_K\s*", cells.formula_text(raw), re.I)):
        tbl["alpha_corr_ppm_per_K"], _ = value("alpha_corr_ppm_per_K")
    else:
        tbl.pop("alpha_corr_ppm_per_K", None)
    xyz = [value(f"fixture_{a}_mm") for a in "xyz"]
    if "fixture_mm" in tbl or any(d for _x, d in xyz) or any(x != 0 for x, _d in xyz):
        tbl["fixture_mm"] = [x for x, _d in xyz]
    if tbl.get("corrected") is False:
        tbl.pop("alpha_corr_ppm_per_K", None)
    if not had and changed:             # a table the task did not have: W stays as the cell says
        tbl["enabled"] = bool(value("enabled")[0])
    if had or changed:
        rt.doc["workpiece"] = tbl
