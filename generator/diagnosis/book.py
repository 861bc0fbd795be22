"""The diagnosis workbook and plots (``cmmwb diagnose``, ``docs/recordings.md`` section 3).

Sheets: Instructions, Inputs (alpha, the simulation's parameters, probes, initial alignment of
point records), Records (the recordings as editable inputs, residuals, standardized residuals, the
sensitivity columns of the chosen effects as native formulas of the record cells, residuals after
the refit, chart before/after), Points + Coords (point records: one row per coordinate), Cov (the
simulation's covariance of the records, computed by the core from V_X), GLS (the generalized
least-squares normal equations over the alignment and the chosen columns: MINVERSE/MMULT),
Candidates (the search log of the core), Groups (chi-square per group of records), Results.

Large or rank-deficient cases (more than ``NATIVE_MAX_OBS`` residuals, or a covariance without a
Cholesky factor) carry the whitened residual and columns W r, W X (W C W^T = I, computed by the
core) instead of Cov and its inverse; the normal equations stay native.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from xlfuncs.locator import effects as fx
from xlfuncs.locator.diagnose import Diagnosis, effect_estimates
from xlfuncs.pointcloud import Parameters

from ..workbook.book import FMT_SCI, FMT_UM, Book, ChartSeries, Formula
from ..workbook.xlref import Block, block, cell

NATIVE_MAX_OBS = 160
FMT = "0.000000"
ZFMT = "0.000"


def _probe_no(diag: Diagnosis) -> dict[str, int]:
    return {p: k for k, p in enumerate(diag.prep.design.probe_ids)}


class _Row:
    """Cell addresses of one record (or point) row by column key."""

    def __init__(self, sheet: str, row: int, cols: dict[str, int]):
        self.sheet, self.row, self.cols = sheet, row, cols

    def __getitem__(self, key: str) -> str:
        return cell(self.row, self.cols[key], self.sheet)

    def has(self, key: str) -> bool:
        return key in self.cols


def write_book(diag: Diagnosis, path: Path, *, title_extra: str = "", params: Parameters | None = None,
               source: str = "") -> Path:
    prep = diag.prep
    D = prep.design
    book = Book("diagnose", "diagnosis", "Mismatch locator — recordings against the simulation"
                + (f" ({title_extra})" if title_extra else ""))
    native = prep.C.shape[0] <= NATIVE_MAX_OBS and diag.whitener.mode == "cholesky"
    _instructions(book, diag, native, source)
    inputs = _inputs(book, diag, params)
    if D.kind == "length":
        rows, obs = _length_records(book, diag, inputs)
    else:
        rows, obs = _point_records(book, diag, inputs)
    gls = _gls(book, diag, obs, native)
    _fill_after(book, diag, obs, gls)
    _candidates(book, diag)
    _groups(book, diag)
    cached = _results(book, diag, gls, inputs)
    _chart(book, diag, obs)
    out = book.save(path)
    from ..workbook import cache

    cache.store(out, "diagnose", {"rows": cached})   # Results values for programs that do not calculate
    return out


# -- instructions, inputs ------------------------------------------------------------------------

def _instructions(book: Book, diag: Diagnosis, native: bool, source: str) -> None:
    prep = diag.prep
    book.para("What this workbook is", bold=True)
    book.para(
        f"Recordings ({prep.rec.n} {prep.design.kind} records{', ' + source if source else ''}) compared "
        "with the simulation of the task: the residuals, their chi-square against the simulation's "
        "covariance (Forbes 2025 eq. 28, propagated to the records), the candidate effects the core "
        "tested (docs/recordings.md section 4) and the refit with the chosen ones.",
        "The refit is live: the normal equations of generalized least squares, b = (X' C^-1 X)^-1 X' "
        "C^-1 r, are native MMULT/MINVERSE formulas over the chosen sensitivity columns, and those "
        "columns are formulas of the record cells (probe offsets, normals, temperatures, times).")
    book.gap()
    book.para("Plain-language answer", bold=True)
    book.para(diag.summary)
    book.gap()
    book.para("Sheets", bold=True)
    lines = [
        "Inputs — alpha (the significance level, editable), the simulation's parameters and probes "
        "(grey: the covariance was computed from them by the core).",
        ("Records — one row per length record: inputs (yellow), direction n_a, ram positions u = x - p, "
         "residual r = (measured - reference), u = sqrt(C_aa), z = r/u, the chosen effects' "
         "sensitivity columns, fitted values and residuals after the refit.") if prep.design.kind == "length" else
        ("Points — one row per point record: inputs (yellow), nominal point in machine coordinates "
         "y = R0 x_nom + t0 (R0, t0 the initial alignment on Inputs), ram position y - p. Coords — one row "
         "per coordinate: residual, the alignment columns (nuisance) and the chosen effects' columns."),
        ("Cov — the covariance C of the residuals (µm², grey: computed by the core from V_X). GLS — "
         "MINVERSE(C), C^-1 X, C^-1 r, the normal equations and the estimates.") if native else
        ("Whitened — W r and W X with W C W^T = I (grey: computed by the core from the covariance C, "
         f"which is too large ({prep.C.shape[0]} rows) or singular for native MINVERSE); GLS — the "
         "normal equations on them."),
        "Candidates — the search of the core: every candidate, its Δχ², raw and Bonferroni-adjusted "
        "p-values, verdict and why it was not identifiable or aliased; the two gates (omnibus or "
        "targeted, alpha/2 each), the outliers left out and the noise level (docs/recordings.md section 7).",
        "Groups — chi-square of the records of each group (group, probe, probing, direction, temperature "
        "and time bands): where the mismatch concentrates.",
        "Results — the numbers of diagnosis.json, as formulas.",
    ]
    book.para(*lines)
    book.gap()
    book.para("Conventions", bold=True)
    book.para(
        "Units: coordinates mm, residuals and uncertainties µm; estimates in the units of docs/recordings.md section 4 "
        "(µm/m, µrad, ppm/K, µm, µrad/m, µm/m per hour, µm/h, ppm/K per m; a periodic error's period in mm).",
        "Sign: measured - true = sum of effects + noise. Angular error motions act with angle kappa*t, t "
        "the carriage travel (x - p)_axis from machine zero; drifts are zero at time_s = 0.",
        "z is the residual divided by its standard uncertainty under the simulation (for point records "
        "with the alignment projected out).")


def _inputs(book: Book, diag: Diagnosis, params: Parameters | None) -> dict:
    ws = book.sheet("Inputs")
    prep = diag.prep
    book.header(ws, 1, 1, ["parameter", "value", "unit", "meaning"])
    book.text(ws, 2, 1, "alpha")
    book.input(ws, 2, 2, "alpha", diag.alpha, lo=0.0, hi=1.0,
               note="significance level: mismatch when p < alpha (docs/recordings.md section 3.1)")
    book.text(ws, 2, 3, "1")
    book.text(ws, 2, 4, "significance level of the chi-square test and of the effect search")
    r = 3
    if params is not None:
        for key in Parameters.__dataclass_fields__:
            book.text(ws, r, 1, key)
            book.number(ws, r, 2, getattr(params, key), fmt="General", computed=True)
            book.text(ws, r, 4, "simulation parameter (Forbes 2025 Table 3 names); the covariance C was "
                                "computed from it by the core")
            r += 1
    ws.column_dimensions["A"].width = 18
    ws.column_dimensions["D"].width = 60
    r += 1
    book.text(ws, r, 1, "Probes (first = reference of probe_qualification)")
    r += 1
    book.header(ws, r, 1, ["probe", "px_mm", "py_mm", "pz_mm"])
    probe_cells = {}
    for k, probe in enumerate(prep.cloud.probes):
        r += 1
        book.text(ws, r, 1, probe.id)
        for c, v in enumerate(probe.offset_mm):
            book.number(ws, r, 2 + c, v, fmt="General", computed=True)
        probe_cells[probe.id] = cell(r, 1, "Inputs")
    out = {"probe_cells": probe_cells, "free_row": r + 2}
    if prep.design.kind == "point":
        r += 2
        book.text(ws, r, 1, "Initial alignment (Kabsch, computed by the core): y = R0 x_nom + t0; "
                            "the GLS alignment columns refine it")
        r += 1
        book.header(ws, r, 1, ["R0", "", "", "t0_mm"])
        R0 = Block("Inputs", r + 1, 1, 3, 3)
        t0 = Block("Inputs", r + 1, 4, 3, 1)
        for a in range(3):
            for b in range(3):
                book.number(ws, r + 1 + a, 1 + b, prep.R0[a, b], fmt="0.000000000", computed=True)
            book.number(ws, r + 1 + a, 4, prep.t0[a], fmt="0.000000", computed=True)
        r += 5
        book.text(ws, r, 1, "centroid c of the nominal points (machine coordinates, mm)")
        out["R0"], out["t0"] = R0, t0
        out["c_row"] = r + 1
        out["free_row"] = r + 3
    return out


def _travel_cells(book: Book, diag: Diagnosis, inputs: dict, sheet: str, cols: dict[str, list[int]],
                  n: int) -> dict[str, tuple[str, str]]:
    """For the chosen straightness effects (docs/recordings.md section 7): the travel of their
    carriage over the records, lo = MIN and hi = MAX of the ram coordinate columns ``cols[axis]``
    of ``sheet`` (rows 2..n+1), on Inputs; {carriage: (lo cell, hi cell)}."""
    periodic = [e for e in dict.fromkeys(e for e, _ in diag.sel_labels) if e in fx.PERIODIC]
    cars = sorted({e[2] for e, _ in diag.sel_labels if e in fx.STRAIGHTNESS} | {e[-1].upper() for e in periodic})
    if not cars:
        return {}
    wi = book.wb["Inputs"]
    r = inputs["free_row"]
    book.text(wi, r, 1, "travel of the carriages over the records (ram coordinates, mm): the straightness "
                        "polynomials P2, P3 are of s = (2 u - lo - hi)/(hi - lo); a periodic error's phase "
                        "is about (lo + hi)/2")
    book.header(wi, r + 1, 1, ["carriage", "lo_mm", "hi_mm"])
    out = {}
    for k, car in enumerate(cars):
        rr = r + 2 + k
        ranges = ",".join(block(2, c, n, 1, sheet) for c in cols[car.lower()])
        book.text(wi, rr, 1, car)
        book.formula(wi, rr, 2, f"=MIN({ranges})")
        book.formula(wi, rr, 3, f"=MAX({ranges})")
        out[car] = (cell(rr, 2, "Inputs"), cell(rr, 3, "Inputs"))
    if periodic:
        r += 3 + len(cars)
        book.text(wi, r, 1, "periodic errors (docs/diagnose.md section 6): the period found by the locator's "
                            "scan (a search, not a formula) and the point (a, b) its sensitivity is linearized at")
        book.header(wi, r + 1, 1, ["effect", "period_mm", "a0_um", "b0_um"], [
            None, "the period of the largest drop of chi-square over the scanned grid, refined; fixed here",
            "a of the fit with the period fixed (the refit's column for the period is the derivative at a0, b0)",
            "b of the fit with the period fixed"])
        for k, name in enumerate(periodic):
            c = diag.candidates[name]
            rr = r + 2 + k
            book.text(wi, rr, 1, name)
            for q, v in enumerate((c.period_mm, *c.lin_ab)):
                book.number(wi, rr, 2 + q, float(v), fmt="0.0000", computed=True)
            out["periodic:" + name[-1]] = tuple(cell(rr, 2 + q, "Inputs") for q in range(3))
            inputs.setdefault("periodic", {})[name] = out["periodic:" + name[-1]]
    return out


def _periodic_formula(par: str, u: str, ax: str, travel: dict) -> str:
    """periodic_<ax> at ram coordinate cell u (no leading '='): SIN (par "a"), COS ("b") of
    w = 2 pi (u - (lo + hi)/2)/P, or the period's column (a0 COS w - b0 SIN w)(-w/P) (par "period_mm");
    effects.periodic_columns and effects.period_column."""
    lo, hi = travel[ax.upper()]
    P, a0, b0 = travel["periodic:" + ax]
    w = f"(2*PI()*({u}-({lo}+{hi})/2)/{P})"
    if par == "a":
        return f"SIN({w})"
    if par == "b":
        return f"COS({w})"
    return f"(({a0}*COS({w})-{b0}*SIN({w}))*(-{w}/{P}))"


def _legendre_formula(k: int, u: str, lo_hi: tuple[str, str]) -> str:
    """P_k(s), k = 2 or 3, of s = (2 u - lo - hi)/(hi - lo) as formula text (no leading '=')."""
    lo, hi = lo_hi
    s = f"((2*{u}-{lo}-{hi})/({hi}-{lo}))"
    return f"(0.5*(3*{s}^2-1))" if k == 2 else f"(0.5*(5*{s}^3-3*{s}))"


def _harmonic_formula(h: str, nx: str, ny: str) -> str:
    """cos k phi ("c<k>") or sin k phi ("s<k>"), k = 2..4, of the azimuth of the normal (nx, ny)
    as polynomials of (c, s) = (nx, ny)/|n_xy|, 0 where |n_xy| <= 0.1 (effects.azimuth_harmonics)."""
    r = f"SQRT({nx}^2+{ny}^2)"
    c, s = f"({nx}/{r})", f"({ny}/{r})"
    poly = {"c2": f"{c}^2-{s}^2", "s2": f"2*{c}*{s}", "c3": f"{c}^3-3*{c}*{s}^2", "s3": f"3*{c}^2*{s}-{s}^3",
            "c4": f"{c}^4-6*{c}^2*{s}^2+{s}^4", "s4": f"4*{c}^3*{s}-4*{c}*{s}^3"}[h]
    return f"IF({r}>{fx.LOBING_MIN_XY},{poly},0)"


def _approach_formula(n: str) -> str:
    """+1 approached along +axis (n < -0.1), -1 along -axis (n > 0.1), else 0 (effects.approach_sign)."""
    t = fx.APPROACH_MIN
    return f"IF({n}<-{t},1,IF({n}>{t},-1,0))"


# -- records -------------------------------------------------------------------------------------

#: columns of the recordings (docs/recordings.md names them without a unit) that are in mm: their
#: headers in the workbook carry it (x1_mm ...)
LENGTH_MM_COLUMNS = frozenset({"x1", "y1", "z1", "x2", "y2", "z2", "p1x", "p1y", "p1z", "p2x", "p2y", "p2z"})
POINT_MM_COLUMNS = frozenset({"x_nom", "y_nom", "z_nom", "x", "y", "z", "px", "py", "pz"})


def shown(key: str, mm_columns) -> str:
    """The header a person reads for column ``key``: ``x1_mm`` for a coordinate of the
    recordings; an effect's design column ``name:label`` with its unit, µm of the record per unit
    of the effect (``squareness_xy:squareness_xy (µm per µrad)``); other keys carry their unit
    already (``residual_um``) or have none (``z``, ``n1x``)."""
    if key in mm_columns:
        return f"{key}_mm"
    if ":" in key:
        name = key.split(":", 1)[0]
        unit = "µm" if name == "outlier" else _display_unit(fx.BY_NAME[name].unit)
        return f"{key} (µm per {unit})"
    return key


def _input_column(book: Book, ws, r0: int, c: int, values) -> None:
    """A column of numeric input cells (styled, unlocked, validated by :meth:`Book.number`)."""
    for k, v in enumerate(values):
        book.number(ws, r0 + k, c, float(v), fmt="General")


def _length_records(book: Book, diag: Diagnosis, inputs: dict):
    prep = diag.prep
    rec, D = prep.rec, prep.design
    ws = book.sheet("Records")
    cols: list[str] = ["id", "x1", "y1", "z1", "x2", "y2", "z2", "reference_mm", "measured_mm"]
    if D.N1 is not None:
        cols += ["n1x", "n1y", "n1z", "n2x", "n2y", "n2z"]
    cols += ["p1x", "p1y", "p1z", "p2x", "p2y", "p2z", "probe1", "probe2"]
    if rec.temperature_C is not None:
        cols.append("temperature_C")
    if rec.time_s is not None:
        cols.append("time_s")
    if rec.group is not None:
        cols.append("group")
    cols += list(rec.extra)
    derived = ["dx_mm", "dy_mm", "dz_mm", "d_mm", "nax", "nay", "naz", "ux1_mm", "uy1_mm", "uz1_mm",
               "ux2_mm", "uy2_mm", "uz2_mm", "residual_um", "u_um", "z"]
    chosen_cols = [f"{e}:{l}" for e, l in diag.sel_labels if e != "alignment"]
    after = ["fitted_um", "residual_after_um", "z_after"]
    header = cols + derived + chosen_cols + after
    ci = {k: i + 1 for i, k in enumerate(header)}
    notes = {"residual_um": "r = (measured - reference) * 1000: the simulation predicts 0",
             "u_um": "standard uncertainty of the residual under the simulation: sqrt(C_aa) (Cov sheet)",
             "z": "standardized residual r/u", "nax": "n_a = (x2 - x1)/d, the direction of the length",
             "ux1_mm": "ram position x - p (Forbes 2025 section 5.3, multiple probes)",
             "fitted_um": "sum of the chosen effects: row of X times b (GLS sheet)",
             "residual_after_um": "r - fitted", "z_after": "(r - fitted)/u"}
    book.header(ws, 1, 1, [shown(h, LENGTH_MM_COLUMNS) for h in header], [notes.get(h) for h in header])
    P1, P2 = D.P1, D.P2
    pid = D.probe_ids
    data = {"x1": rec.X1_mm[:, 0], "y1": rec.X1_mm[:, 1], "z1": rec.X1_mm[:, 2],
            "x2": rec.X2_mm[:, 0], "y2": rec.X2_mm[:, 1], "z2": rec.X2_mm[:, 2],
            "reference_mm": rec.reference_mm, "measured_mm": rec.measured_mm,
            "p1x": P1[:, 0], "p1y": P1[:, 1], "p1z": P1[:, 2], "p2x": P2[:, 0], "p2y": P2[:, 1], "p2z": P2[:, 2]}
    if D.N1 is not None:
        for e, N in (("1", rec.N1), ("2", rec.N2)):
            for a, ax in enumerate("xyz"):
                data[f"n{e}{ax}"] = N[:, a]
    if rec.temperature_C is not None:
        data["temperature_C"] = rec.temperature_C
    if rec.time_s is not None:
        data["time_s"] = rec.time_s
    rows = []
    for k, v in data.items():
        _input_column(book, ws, 2, ci[k], v)
    for a in range(rec.n):
        r = a + 2
        R = _Row("Records", r, ci)
        rows.append(R)
        book.text(ws, r, ci["id"], rec.ids[a])
        book.text(ws, r, ci["probe1"], pid[D.k1[a]])
        book.text(ws, r, ci["probe2"], pid[D.k2[a]])
        if rec.group is not None:
            book.text(ws, r, ci["group"], rec.group[a])
        for k, v in rec.extra.items():
            book.text(ws, r, ci[k], v[a])
        L = {k: cell(r, ci[k]) for k in ci}
        for ax in "xyz":
            book.formula(ws, r, ci[f"d{ax}_mm"], f"={L[ax + '2']}-{L[ax + '1']}")
        book.formula(ws, r, ci["d_mm"], f"=SQRT({L['dx_mm']}^2+{L['dy_mm']}^2+{L['dz_mm']}^2)")
        for ax in "xyz":
            book.formula(ws, r, ci[f"na{ax}"], f"={L['d' + ax + '_mm']}/{L['d_mm']}")
            for e in "12":
                book.formula(ws, r, ci[f"u{ax}{e}_mm"], f"={L[ax + e]}-{L['p' + e + ax]}")
        book.formula(ws, r, ci["residual_um"], f"=({L['measured_mm']}-{L['reference_mm']})*1000")
    obs = {"sheet": "Records", "rows": [R.row for R in rows], "ci": ci, "chosen_cols": chosen_cols,
           "first_X": ci[chosen_cols[0]] if chosen_cols else None, "n_align": 0, "row_of_obs": rows}
    travel = _travel_cells(book, diag, inputs, "Records",
                           {ax: [ci[f"u{ax}1_mm"], ci[f"u{ax}2_mm"]] for ax in "xyz"}, rec.n)
    # the middle of the probed positions along each axis (thermal gradient, section 7)
    pos = {ax: ",".join(block(2, ci[f"{ax}{e}"], rec.n, 1, "Records") for e in "12") for ax in "xyz"}
    travel.update({f"pos_{ax}": (f"MIN({r})", f"MAX({r})") for ax, r in pos.items()})
    for q, label in enumerate(chosen_cols):
        name, par = label.split(":", 1)
        for a, R in enumerate(rows):
            # an outlier left out (docs/recordings.md section 7): its own mean-shift column, 1 on its row
            f = (1.0 if rec.ids[a] == par else 0.0) if name == "outlier" else \
                length_formula(name, par, R, inputs["probe_cells"], travel)
            _value_or_formula(book, ws, R.row, ci[label], f)
    ws.freeze_panes = "B2"
    return rows, obs


def _value_or_formula(book: Book, ws, r: int, c: int, f: str | float) -> None:
    if isinstance(f, str):
        book.formula(ws, r, c, f, fmt="0.000000E+00")
    else:
        ws.cell(row=r, column=c).value = float(f)


def _na_dot(R: _Row, v: tuple[str, str, str]) -> str:
    terms = [f"{R['na' + ax]}*{v[a]}" for a, ax in enumerate("xyz") if v[a] != "0"]
    return "(" + "+".join(terms) + ")" if terms else "0"


def _rot_vec(rot: str, p: tuple[str, str, str]) -> tuple[str, str, str]:
    """e_R x p as formula strings (A: (0, -pz, py), B: (pz, 0, -px), C: (-py, px, 0))."""
    px, py, pz = p
    return {"A": ("0", f"(-{pz})", py), "B": (pz, "0", f"(-{px})"), "C": (f"(-{py})", px, "0")}[rot]


def length_formula(name: str, par: str, R: _Row, probe_cells: dict[str, str],
                   travel: dict[str, tuple[str, str]] | None = None) -> str:
    """Sensitivity of a length record to one parameter, as a formula of its row (effects.py);
    ``travel``: the lo/hi cells of the straightness carriages (:func:`_travel_cells`)."""
    du = {ax: f"({R['u' + ax + '2_mm']}-{R['u' + ax + '1_mm']})" for ax in "xyz"}
    ndu = "(" + "+".join(f"{R['na' + ax]}*{du[ax]}" for ax in "xyz") + ")"
    if name == "scale":
        return f"=0.001*{ndu}"
    if name.startswith("scale_") and name[-1] in "xyz":
        ax = name[-1]
        return f"=0.001*{R['na' + ax]}*{du[ax]}"
    if name.startswith("squareness_"):
        return f"=0.001*{R['na' + name[-2]]}*{du[name[-1]]}"
    if name == "thermal_expansion":
        return f"=0.001*({R['temperature_C']}-20)*{R['reference_mm']}"
    if name == "probe_radius":
        n2 = _na_dot(R, tuple(R[f"n2{ax}"] for ax in "xyz"))
        n1 = _na_dot(R, tuple(R[f"n1{ax}"] for ax in "xyz"))
        return f"={n2}-{n1}"
    if name == "probe_qualification":
        pid, comp = par.split(".d")
        k = probe_cells[pid]
        return f"={R['na' + comp]}*(EXACT({R['probe2']},{k})*1-EXACT({R['probe1']},{k})*1)"
    if name in fx.ANGULAR:
        rot, car = name[1], name[2].lower()
        v1 = _rot_vec(rot, tuple(R[f"p1{ax}"] for ax in "xyz"))
        v2 = _rot_vec(rot, tuple(R[f"p2{ax}"] for ax in "xyz"))
        return f"=0.000001*({R['u' + car + '2_mm']}*{_na_dot(R, v2)}-{R['u' + car + '1_mm']}*{_na_dot(R, v1)})"
    if name == "scale_drift":
        return f"=0.001*({R['time_s']}/3600)*{ndu}"
    if name in fx.STRAIGHTNESS:
        k, car, dev = int(par[1]), name[2], name[1].lower()
        p2 = _legendre_formula(k, R[f"u{car.lower()}2_mm"], travel[car])
        p1 = _legendre_formula(k, R[f"u{car.lower()}1_mm"], travel[car])
        return f"={R['na' + dev]}*({p2}-{p1})"
    if name in fx.REVERSAL:
        ax = name[-1]
        return f"={R['na' + ax]}*({_approach_formula(R['n2' + ax])}-{_approach_formula(R['n1' + ax])})"
    if name == "probe_lobing":
        pid, h = par.split(".")
        k = probe_cells[pid]
        n2 = _na_dot(R, tuple(R[f"n2{a}"] for a in "xyz"))
        n1 = _na_dot(R, tuple(R[f"n1{a}"] for a in "xyz"))
        return (f"={n2}*{_harmonic_formula(h, R['n2x'], R['n2y'])}*EXACT({R['probe2']},{k})*1"
                f"-{n1}*{_harmonic_formula(h, R['n1x'], R['n1y'])}*EXACT({R['probe1']},{k})*1")
    if name in fx.PERIODIC:
        ax = name[-1]
        f2 = _periodic_formula(par, R[f"u{ax}2_mm"], ax, travel)
        f1 = _periodic_formula(par, R[f"u{ax}1_mm"], ax, travel)
        return f"={R['na' + ax]}*({f2}-{f1})"
    if name in fx.GRADIENT:
        ax = name[-1]
        lo, hi = travel["pos_" + ax]
        mid = f"(({R[ax + '1']}+{R[ax + '2']})/2-({lo}+{hi})/2)"
        return f"=0.000001*({R['temperature_C']}-20)*{R['reference_mm']}*{mid}"
    raise ValueError(f"no length formula for {name}")


def _point_records(book: Book, diag: Diagnosis, inputs: dict):
    prep = diag.prep
    rec, D = prep.rec, prep.design
    ws = book.sheet("Points")
    cols = ["id", "x_nom", "y_nom", "z_nom", "x", "y", "z"]
    if rec.N is not None:
        cols += ["nx", "ny", "nz"]
    cols += ["px", "py", "pz", "probe"]
    if rec.temperature_C is not None:
        cols.append("temperature_C")
    if rec.time_s is not None:
        cols.append("time_s")
    if rec.group is not None:
        cols.append("group")
    cols += list(rec.extra)
    derived = ["yx_mm", "yy_mm", "yz_mm", "ux_mm", "uy_mm", "uz_mm"]
    header = cols + derived
    ci = {k: i + 1 for i, k in enumerate(header)}
    notes = {"yx_mm": "nominal point in machine coordinates y = R0 x_nom + t0 (Inputs)",
             "ux_mm": "ram position y - p"}
    book.header(ws, 1, 1, [shown(h, POINT_MM_COLUMNS) for h in header], [notes.get(h) for h in header])
    data = {"x_nom": rec.X_nom_mm[:, 0], "y_nom": rec.X_nom_mm[:, 1], "z_nom": rec.X_nom_mm[:, 2],
            "x": rec.X_mm[:, 0], "y": rec.X_mm[:, 1], "z": rec.X_mm[:, 2],
            "px": D.P[:, 0], "py": D.P[:, 1], "pz": D.P[:, 2]}
    if rec.N is not None:
        for a, ax in enumerate("xyz"):
            data[f"n{ax}"] = rec.N[:, a]
    if rec.temperature_C is not None:
        data["temperature_C"] = rec.temperature_C
    if rec.time_s is not None:
        data["time_s"] = rec.time_s
    R0, t0 = inputs["R0"], inputs["t0"]
    prow = []
    for k, v in data.items():
        _input_column(book, ws, 2, ci[k], v)
    for i in range(rec.n):
        r = i + 2
        R = _Row("Points", r, ci)
        prow.append(R)
        book.text(ws, r, ci["id"], rec.ids[i])
        book.text(ws, r, ci["probe"], D.probe_ids[D.k[i]])
        if rec.group is not None:
            book.text(ws, r, ci["group"], rec.group[i])
        for k, v in rec.extra.items():
            book.text(ws, r, ci[k], v[i])
        L = {k: cell(r, ci[k]) for k in ci}
        for a, ax in enumerate("xyz"):
            book.formula(ws, r, ci[f"y{ax}_mm"],
                         f"={R0.cell(a, 0)}*{L['x_nom']}+{R0.cell(a, 1)}*{L['y_nom']}+{R0.cell(a, 2)}*{L['z_nom']}"
                         f"+{t0.cell(a, 0)}")
            book.formula(ws, r, ci[f"u{ax}_mm"], f"={L['y' + ax + '_mm']}-{L['p' + ax]}")
    ws.freeze_panes = "B2"
    # centroid of the nominal points on Inputs
    wi = book.wb["Inputs"]
    crow = inputs["c_row"]
    centroid = {}
    for a, ax in enumerate("xyz"):
        book.text(wi, crow, 1 + 2 * a, f"c{ax}_mm")
        book.formula(wi, crow, 2 + 2 * a, f"=AVERAGE({block(2, ci[f'y{ax}_mm'], rec.n, 1, 'Points')})")
        centroid[ax] = cell(crow, 2 + 2 * a, "Inputs")
    # one row per coordinate
    wc = book.sheet("Coords")
    dims = D.dims
    al = [l for e, l in diag.sel_labels if e == "alignment"]
    chosen_cols = [f"{e}:{l}" for e, l in diag.sel_labels if e != "alignment"]
    header = ["point", "axis", "residual_um", "u_um", "z"] + al + chosen_cols + \
             ["fitted_um", "residual_after_um", "z_after", "baseline_um", "residual_before_um"]
    cc = {k: i + 1 for i, k in enumerate(header)}
    book.header(wc, 1, 1, [shown(h, ()) for h in header], [
        None, None, "r = (x - y) * 1000 (y: nominal in machine coordinates)",
        "standard uncertainty of the residual after the baseline alignment: sqrt(C_qq - a_q Ma^-1 a_q')",
        "(r - baseline)/u", *["alignment (nuisance): translation µm, small rotation µrad about the centroid"] * len(al),
        *[None] * len(chosen_cols), "row of X (effects) times b", "r - alignment - fitted",
        "(r - alignment - fitted)/u", "alignment of the baseline fit (alignment columns times b0)",
        "r - baseline"])
    travel = _travel_cells(book, diag, inputs, "Points", {ax: [ci[f"u{ax}_mm"]] for ax in "xyz"}, rec.n)
    rows = []
    for i in range(rec.n):
        P = prow[i]
        for a in range(dims):
            r = 2 + dims * i + a
            ax = "xyz"[a]
            R = _Row("Coords", r, cc)
            rows.append(R)
            book.text(wc, r, cc["point"], rec.ids[i])
            book.text(wc, r, cc["axis"], ax)
            book.formula(wc, r, cc["residual_um"], f"=({P[ax]}-{P['y' + ax + '_mm']})*1000")
            for lab in al:
                _value_or_formula(book, wc, r, cc[lab], alignment_formula(lab, a, P, centroid))
            for label in chosen_cols:
                name, par = label.split(":", 1)
                f = (1.0 if par == f"{rec.ids[i]}.{ax}" else 0.0) if name == "outlier" else \
                    point_formula(name, par, a, P, centroid, inputs["probe_cells"], travel)
                _value_or_formula(book, wc, r, cc[label], f)
    wc.freeze_panes = "C2"
    obs = {"sheet": "Coords", "rows": [R.row for R in rows], "ci": cc, "chosen_cols": chosen_cols,
           "first_X": cc[al[0]] if al else cc.get(chosen_cols[0]) if chosen_cols else None,
           "n_align": len(al), "row_of_obs": rows}
    return rows, obs


def alignment_formula(label: str, a: int, P: _Row, c: dict) -> str | float:
    ax = "xyz"[a]
    if label.startswith("t"):
        return 1.0 if label[1] == ax else 0.0
    w = label[1]
    rel = {k: f"({P['y' + k + '_mm']}-{c[k]})" for k in "xyz"}
    # omega x (y - c): w_x -> (0, -rz, ry); w_y -> (rz, 0, -rx); w_z -> (-ry, rx, 0)
    table = {"x": ("0", f"-{rel['z']}", rel["y"]), "y": (rel["z"], "0", f"-{rel['x']}"),
             "z": (f"-{rel['y']}", rel["x"], "0")}
    e = table[w][a]
    return 0.0 if e == "0" else f"=0.001*{e}"


def point_formula(name: str, par: str, a: int, P: _Row, c: dict, probe_cells: dict[str, str],
                  travel: dict[str, tuple[str, str]] | None = None) -> str | float:
    """Sensitivity of coordinate a of a point record to one parameter (effects.py, point rows);
    ``travel``: the lo/hi cells of the straightness carriages (:func:`_travel_cells`)."""
    ax = "xyz"[a]
    rel = lambda k: f"({P['u' + k + '_mm']}-{c[k]})"   # ram position about the centroid
    if name == "scale":
        return f"=0.001*{rel(ax)}"
    if name.startswith("scale_") and name[-1] in "xyz":
        return f"=0.001*{rel(ax)}" if name[-1] == ax else 0.0
    if name.startswith("squareness_"):
        return f"=0.001*{rel(name[-1])}" if name[-2] == ax else 0.0
    if name == "thermal_expansion":
        return f"=0.001*({P['temperature_C']}-20)*({P['y' + ax + '_mm']}-{c[ax]})"
    if name == "probe_radius":
        return f"={P['n' + ax]}"
    if name == "probe_qualification":
        pid, comp = par.split(".d")
        return f"=EXACT({P['probe']},{probe_cells[pid]})*1" if comp == ax else 0.0
    if name in fx.ANGULAR:
        rot, car = name[1], name[2].lower()
        v = _rot_vec(rot, tuple(P[f"p{k}"] for k in "xyz"))[a]
        return 0.0 if v == "0" else f"=0.000001*{P['u' + car + '_mm']}*{v}"
    if name == "scale_drift":
        return f"=0.001*({P['time_s']}/3600)*{rel(ax)}"
    if name == "offset_drift":
        return f"={P['time_s']}/3600" if par == f"v{ax}" else 0.0
    if name in fx.STRAIGHTNESS:
        car = name[2]
        return ("=" + _legendre_formula(int(par[1]), P[f"u{car.lower()}_mm"], travel[car])
                if name[1].lower() == ax else 0.0)
    if name in fx.REVERSAL:
        return "=" + _approach_formula(P["n" + ax]) if name[-1] == ax else 0.0
    if name == "probe_lobing":
        pid, h = par.split(".")
        return (f"={P['n' + ax]}*{_harmonic_formula(h, P['nx'], P['ny'])}"
                f"*EXACT({P['probe']},{probe_cells[pid]})*1")
    if name in fx.PERIODIC:
        return "=" + _periodic_formula(par, P[f"u{ax}_mm"], ax, travel) if name[-1] == ax else 0.0
    if name in fx.GRADIENT:
        g = name[-1]
        return (f"=0.000001*({P['temperature_C']}-20)*({P['y' + g + '_mm']}-{c[g]})"
                f"*({P['y' + ax + '_mm']}-{c[ax]})")
    raise ValueError(f"no point formula for {name}")


# -- the GLS -------------------------------------------------------------------------------------

def _gls(book: Book, diag: Diagnosis, obs: dict, native: bool) -> dict:
    prep = diag.prep
    n = prep.C.shape[0]
    p = diag.X_sel.shape[1]
    p0 = obs["n_align"]
    sheet, ci = obs["sheet"], obs["ci"]
    r0 = obs["rows"][0]
    rvec = Block(sheet, r0, ci["residual_um"], n, 1)
    X = Block(sheet, r0, obs["first_X"], n, p) if p else None
    ws = book.sheet("GLS")
    out = {"rvec": rvec, "X": X, "p": p, "p0": p0, "native": native}
    if native:
        wc = book.sheet("Cov")
        book.text(wc, 1, 1, "C (µm²): covariance of the residuals under the simulation, G V_X G' "
                            "(Forbes 2025 eqs. 28-29), computed by the core")
        for i in range(n):
            for j in range(n):
                book.number(wc, 2 + i, 1 + j, prep.C[i, j], fmt=FMT_SCI, computed=True)
        Cb = Block("Cov", 2, 1, n, n)
        wi = book.sheet("Cinv")
        book.text(wi, 1, 1, "C^-1 = MINVERSE(C)")
        Ci = Block("Cinv", 2, 1, n, n)
        book.array(Ci, f"=MINVERSE({Cb.ref})", fmt=FMT_SCI, note="inverse of the covariance C")
        from openpyxl.utils import get_column_letter

        for w_ in (wc, wi):
            for j in range(n):   # 0.000E+00 of a negative number: 10 characters
                w_.column_dimensions[get_column_letter(1 + j)].width = 11
            book.print_setup(w_, matrix=(n, n), caption=(
                f"{w_.title}: top-left corner of the {n} x {n} matrix; the whole matrix is in the workbook, "
                "not in the printout"))
        out["C"] = Cb
        # column blocks: C^-1 r, C^-1 X
        book.text(ws, 1, 1, "C^-1 r")
        Cir = Block("GLS", 2, 1, n, 1)
        book.array(Cir, f"=MMULT({Ci.ref},{rvec.ref})")
        if p:
            book.text(ws, 1, 2, "C^-1 X")
            CiX = Block("GLS", 2, 2, n, p)
            book.array(CiX, f"=MMULT({Ci.ref},{X.ref})")
        out["Ci"], out["Cir"] = Ci, Cir
        c0 = 3 + p
    else:
        ww = book.sheet("Whitened")
        yw = diag.whitener(prep.r_um)
        # the structured covariance (xlfuncs.locator.structured) gives coordinates with the same inner
        # products a' C^-1 b, fewer than n of them: the rank of C is then a cell of its own
        k = diag.whitener.rank if diag.whitener.mode != "structured" else len(yw)
        book.text(ww, 1, 1, f"W r and W X with W C W' = I ({diag.whitener.mode}; computed by the core, "
                            f"C is {n} x {n})")
        if diag.whitener.mode == "structured":
            book.text(ww, 1, p + 3, "rank of C")
            book.number(ww, 1, p + 4, diag.whitener.rank, fmt="0", computed=True)
            out["rank_ref"] = cell(1, p + 4, "Whitened")
        Xw = diag.whitener(diag.X_sel) if p else np.zeros((k, 0))
        book.header(ww, 2, 1, ["Wr"] + [f"W {l}" for _, l in diag.sel_labels])
        for i in range(k):
            book.number(ww, 3 + i, 1, yw[i], fmt="0.000000E+00", computed=True)
            for j in range(p):
                book.number(ww, 3 + i, 2 + j, Xw[i, j], fmt="0.000000E+00", computed=True)
        out["yw"] = Block("Whitened", 3, 1, k, 1)
        out["Xw"] = Block("Whitened", 3, 2, k, p) if p else None
        out["k"] = k
        c0 = 1
    # normal equations block to the right (native) or on GLS (whitened)
    row = 1
    def label(r, c, text):
        book.text(ws, r, c, text)
    if p:
        label(row, c0, "M = X' C^-1 X" if native else "M = (WX)'(WX)")
        M = Block("GLS", row + 1, c0, p, p)
        if native:
            book.array(M, f"=MMULT(TRANSPOSE({X.ref}),{Block('GLS', 2, 2, n, p).ref})", fmt="0.000000E+00")
            Xty = f"MMULT(TRANSPOSE({X.ref}),{out['Cir'].ref})"
        else:
            book.array(M, f"=MMULT(TRANSPOSE({out['Xw'].ref}),{out['Xw'].ref})", fmt="0.000000E+00")
            Xty = f"MMULT(TRANSPOSE({out['Xw'].ref}),{out['yw'].ref})"
        row += p + 2
        label(row, c0, "X' C^-1 r" if native else "(WX)'(Wr)")
        g = Block("GLS", row + 1, c0, p, 1)
        book.array(g, f"={Xty}", fmt="0.000000E+00")
        row += p + 2
        label(row, c0, "M^-1 (covariance of the estimates)")
        Minv = Block("GLS", row + 1, c0, p, p)
        book.array(Minv, f"=MINVERSE({M.ref})", fmt="0.000000E+00")
        row += p + 2
        label(row, c0, "parameter")
        label(row, c0 + 1, "b = M^-1 X' C^-1 r")
        label(row, c0 + 2, "u(b) = sqrt(M^-1_jj)")
        label(row, c0 + 3, "unit")
        b = Block("GLS", row + 1, c0 + 1, p, 1)
        book.array(b, f"=MMULT({Minv.ref},{g.ref})", fmt=FMT_UM,
                   note="GLS estimates: alignment (nuisance) and the chosen effects")
        for j, (e, l) in enumerate(diag.sel_labels):
            book.text(ws, row + 1 + j, c0, l if e == "alignment" else (e if l == e else f"{e} {l}"))
            book.formula(ws, row + 1 + j, c0 + 2, f"=SQRT({Minv.cell(j, j)})", fmt=FMT_UM)
            unit = (("µm" if l.startswith("t") else "µrad") if e == "alignment" else "µm" if e == "outlier"
                    else "mm" if l == "period_mm" else _display_unit(fx.BY_NAME[e].unit))
            book.text(ws, row + 1 + j, c0 + 3, unit)
        out.update(M=M, g=g, Minv=Minv, b=b, u_col=c0 + 2, b_row=row + 1, c0=c0)
        row += p + 2
        if p0:
            label(row, c0, "baseline: alignment only, b0 = Ma^-1 (A' C^-1 r)")
            Ma_inv = Block("GLS", row + 1, c0, p0, p0)
            book.array(Ma_inv, f"=MINVERSE({M.sub(0, 0, p0, p0).ref})", fmt="0.000000E+00")
            b0 = Block("GLS", row + 1, c0 + p0 + 1, p0, 1)
            book.array(b0, f"=MMULT({Ma_inv.ref},{g.sub(0, 0, p0, 1).ref})", fmt="0.000000E+00")
            out.update(Ma_inv=Ma_inv, b0=b0)
            row += p0 + 2
    out["stats_row"] = row
    return out


def _fill_after(book: Book, diag: Diagnosis, obs: dict, gls: dict) -> None:
    """Per-row u, z, fitted, residual after; then the statistics on GLS."""
    sheet, ci = obs["sheet"], obs["ci"]
    ws = book.wb[sheet]
    p, p0 = gls["p"], gls["p0"]
    native = gls["native"]
    n = len(obs["rows"])
    for q, r in enumerate(obs["rows"]):
        L = lambda k: cell(r, ci[k])
        # u: sqrt of the diagonal of C (baseline-adjusted for point records)
        if native:
            cqq = gls["C"].cell(q, q)
            if p0:
                arow = block(r, obs["first_X"], 1, p0, sheet)
                book.array(Block(sheet, r, ci["u_um"], 1, 1),
                           f"=SQRT({cqq}-MMULT(MMULT({arow},{gls['Ma_inv'].ref}),TRANSPOSE({arow})))",
                           fmt=FMT)
            else:
                book.formula(ws, r, ci["u_um"], f"=SQRT({cqq})", fmt=FMT)
        else:
            book.number(ws, r, ci["u_um"], diag.u_obs[q], fmt=FMT, computed=True)
        if p0:
            arow = block(r, obs["first_X"], 1, p0)
            book.array(Block(sheet, r, ci["baseline_um"], 1, 1),
                       f"=MMULT({arow},{gls['b0'].ref})", fmt=FMT)
            book.formula(ws, r, ci["residual_before_um"], f"={L('residual_um')}-{L('baseline_um')}", fmt=FMT)
            before = L("residual_before_um")
        else:
            before = L("residual_um")
        book.formula(ws, r, ci["z"], f"={before}/{L('u_um')}", fmt=ZFMT)
        if p - p0 > 0:
            xrow = block(r, obs["first_X"] + p0, 1, p - p0)
            book.array(Block(sheet, r, ci["fitted_um"], 1, 1),
                       f"=MMULT({xrow},{gls['b'].sub(p0, 0, p - p0, 1).ref})", fmt=FMT)
        else:
            ws.cell(row=r, column=ci["fitted_um"]).value = 0.0
        if p0:
            arow = block(r, obs["first_X"], 1, p0)
            book.array(Block(sheet, r, ci["residual_after_um"], 1, 1),
                       f"={L('residual_um')}-MMULT({arow},{gls['b'].sub(0, 0, p0, 1).ref})-{L('fitted_um')}",
                       fmt=FMT)
        else:
            book.formula(ws, r, ci["residual_after_um"], f"={L('residual_um')}-{L('fitted_um')}", fmt=FMT)
        book.formula(ws, r, ci["z_after"], f"={L('residual_after_um')}/{L('u_um')}", fmt=ZFMT)
    # statistics
    wg = book.wb["GLS"]
    r0 = obs["rows"][0]
    e_after = Block(sheet, r0, ci["residual_after_um"], n, 1)
    e_before = Block(sheet, r0, ci["residual_before_um" if p0 else "residual_um"], n, 1)
    row = gls["stats_row"]
    c0 = gls.get("c0", 3)
    stats = {}

    def stat(key, formula, note, array=False, fmt=FMT):
        nonlocal row
        book.text(wg, row, c0, key)
        if array:
            book.array(Block("GLS", row, c0 + 1, 1, 1), formula, fmt=fmt, note=note)
        else:
            book.formula(wg, row, c0 + 1, formula, note=note, fmt=fmt)
        stats[key] = cell(row, c0 + 1, "GLS")
        row += 1

    if native:
        Ci = gls["Ci"].ref
        stat("chi2_before", f"=MMULT(TRANSPOSE({e_before.ref}),MMULT({Ci},{e_before.ref}))",
             "r0' C^-1 r0, r0 the residual of the baseline (docs/recordings.md section 3.1)", array=True)
        stat("dof_before", f"=COUNT({e_before.ref})-{p0}", "records (coordinates) minus alignment parameters",
             fmt="0")
        stat("chi2_after", f"=MMULT(TRANSPOSE({e_after.ref}),MMULT({Ci},{e_after.ref}))",
             "e' C^-1 e after the refit", array=True)
        stat("dof_after", f"=COUNT({e_after.ref})-{p}", "minus every fitted parameter", fmt="0")
    else:
        yw = gls["yw"].ref
        count = gls.get("rank_ref") or f"COUNT({yw})"
        if p:
            Xw = gls["Xw"]
            if p0:
                stat("chi2_before", f"=SUMSQ({yw}-MMULT({Xw.sub(0, 0, gls['k'], p0).ref},{gls['b0'].ref}))",
                     "|W r - W A b0|^2", array=True)
            else:
                stat("chi2_before", f"=SUMSQ({yw})", "|W r|^2")
            stat("dof_before", f"={count}-{p0}", "rank of C minus alignment parameters", fmt="0")
            stat("chi2_after", f"=SUMSQ({yw}-MMULT({Xw.ref},{gls['b'].ref}))", "|W r - W X b|^2", array=True)
        else:
            stat("chi2_before", f"=SUMSQ({yw})", "|W r|^2")
            stat("dof_before", f"={count}", "rank of C", fmt="0")
            stat("chi2_after", f"=SUMSQ({yw})", "no effect chosen")
        stat("dof_after", f"={count}-{p}", "minus every fitted parameter", fmt="0")
    stat("p_before", f"=CHIDIST({stats['chi2_before']},{stats['dof_before']})",
         "chi-square tail probability", fmt=FMT_SCI)
    # the targeted gate (docs/recordings.md section 7): the smallest Bonferroni-adjusted p-value of the
    # candidates of the first step, from the core's search (Candidates sheet)
    book.text(wg, row, c0, "p_targeted")
    book.number(wg, row, c0 + 1, math.exp(diag.logp_targeted) if diag.targeted_K else 1.0, fmt=FMT_SCI,
                computed=True)
    stats["p_targeted"] = cell(row, c0 + 1, "GLS")
    row += 1
    book.text(wg, row, c0, "mismatch")
    book.formula(wg, row, c0 + 1, f"=IF(OR({stats['p_before']}<alpha/2,{stats['p_targeted']}<alpha/2),"
                                  f"\"yes\",\"no\")", fmt=None,
                 note="two gates, alpha/2 each: the omnibus chi-square or the targeted test (docs/recordings.md section 7)")
    stats["mismatch"] = cell(row, c0 + 1, "GLS")
    row += 1
    stat("p_after", f"=CHIDIST({stats['chi2_after']},{stats['dof_after']})",
         "chi-square tail probability of what remains after the refit", fmt=FMT_SCI)
    book.text(wg, row, c0, "explained")
    book.formula(wg, row, c0 + 1, f"=IF({stats['p_after']}>=alpha,\"yes\",\"no\")", fmt=None,
                 note="the remaining chi-square passes: p_after >= alpha (docs/recordings.md section 7)")
    stats["explained"] = cell(row, c0 + 1, "GLS")
    row += 1
    stat("chi2_per_dof_before", f"={stats['chi2_before']}/{stats['dof_before']}", "")
    stat("chi2_per_dof_after", f"={stats['chi2_after']}/{stats['dof_after']}", "")
    stat("rms_before_um", f"=SQRT(SUMSQ({e_before.ref})/COUNT({e_before.ref}))", "RMS of the residuals (µm)")
    stat("rms_after_um", f"=SQRT(SUMSQ({e_after.ref})/COUNT({e_after.ref}))", "RMS after the refit (µm)")
    if diag.noise_scale:
        stat("noise_scale", f"=SQRT({stats['chi2_per_dof_after']})",
             "the declared uncertainties are too small by this factor: sqrt(chi2/dof) after the refit "
             "(docs/recordings.md section 7, noise level)")
        stat("u_noise_scale", f"={stats['noise_scale']}/SQRT(2*{stats['dof_after']})",
             "standard uncertainty of the noise scale, s / sqrt(2 dof)")
    gls["stats"] = stats


# -- search log, groups, results, chart ----------------------------------------------------------

_CANDIDATE_FORMATS = {"step": "0", "df": "0", "delta_chi2": "0.000", "p_value": "0.00E+00",
                      "p_adjusted": "0.00E+00"}


def _discrepancy_rows(book: Book, ws, r: int, d: dict) -> int:
    """The discrepancy candidate of docs/recordings.md section 7 (tried last, when the named effects
    leave the refit unexplained): the core's numbers, as the search log shows the other candidates."""
    verdict = "chosen" if d["chosen"] else "not significant"
    book.text(ws, r, 1, f"discrepancy ({verdict}): a smooth field over the ram position, degree 2..{d['degree']} "
                        f"(degrees tried {d['degrees_tried']}, {d['test']} test, Bonferroni over the degrees); "
                        f"largest change {d['size_um']:.3g} µm along {d['axis']} at record {d['record']}")
    r += 1
    keys = ("df", "delta_chi2", "p_value", "p_adjusted", "chi2_after", "dof_after", "p_after", "size_um",
            "rms_after_um")
    book.header(ws, r, 1, list(keys))
    r += 1
    for k, key in enumerate(keys):
        ws.cell(row=r, column=1 + k).value = d[key]
        ws.cell(row=r, column=1 + k).number_format = {"df": "0", "dof_after": "0", "p_value": "0.00E+00",
                                                      "p_adjusted": "0.00E+00", "p_after": "0.00E+00"}.get(key, "0.000")
    return r + 2


def _candidates(book: Book, diag: Diagnosis) -> None:
    ws = book.sheet("Candidates")
    j = diag.to_json()
    book.text(ws, 1, 1, "The search of the core (docs/recordings.md section 3.3): GLS forward selection, likelihood-ratio "
                        "test Δχ² with Bonferroni correction for the candidates tested in each step")
    cols = ["name", "verdict", "step", "df", "delta_chi2", "p_value", "p_adjusted", "unit", "reason"]
    book.header(ws, 2, 1, cols)
    for r, c in enumerate(j["candidates"], start=3):
        book.text(ws, r, 1, c["name"])
        book.text(ws, r, 2, c["status"])
        for k, key in enumerate(("step", "df", "delta_chi2", "p_value", "p_adjusted")):
            v = c[key]
            if v is not None and (key != "df" or c["status"] in ("chosen", "indicated", "tested")):
                cell_ = ws.cell(row=r, column=3 + k)
                cell_.value = float(v) if isinstance(v, float) else v
                cell_.number_format = _CANDIDATE_FORMATS[key]
        book.text(ws, r, 8, _display_unit(fx.BY_NAME[c["name"]].unit))
        if c["reason"]:
            book.text(ws, r, 9, c["reason"], wrap=True)     # wrapped: the sheet prints on the page width
            ws.row_dimensions[r].height = 13.0 * max(1, math.ceil(len(c["reason"]) / 72))
    ws.column_dimensions["A"].width = 20
    ws.column_dimensions["B"].width = 16
    for col in "EFG":
        ws.column_dimensions[col].width = 12
    ws.column_dimensions["I"].width = 70
    r = len(j["candidates"]) + 5
    # second edition (docs/recordings.md section 7): the gates, outliers, noise level
    book.text(ws, r, 1, f"gate: {j['gate'] or 'none'} (omnibus p = {j['p_before']:.3g}, targeted p = "
                        f"{(j['p_targeted'] if j['p_targeted'] is not None else 1.0):.3g}, each judged at alpha/2); "
                        f"explained: {'yes' if j['explained'] else 'no'} (p_after = {j['p_after']:.3g})"
              if j["p_after"] is not None else f"gate: {j['gate'] or 'none'}")
    r += 1
    book.text(ws, r, 1, f"an effect is named (chosen) at p_adjusted < {j['alpha_name']:.3g}; between that and "
                        f"alpha = {j['alpha']:.3g} it is only indicated, not applied (docs/recordings.md section 7)")
    r += 1
    for ind in j["indicated"]:
        book.text(ws, r, 1, f"indicated: {ind['name']} (p_adjusted = {ind['p_adjusted']:.3g}); see its row above")
        r += 1
    if j["noise_scale"]:
        ns = j["noise_scale"]
        book.text(ws, r, 1, f"noise level: the declared uncertainties are too small by {ns['estimate']:.4g} "
                            f"(u = {ns['u']:.2g}); no structure a candidate or group explains")
        r += 1
    if j.get("discrepancy"):
        r = _discrepancy_rows(book, ws, r, j["discrepancy"])
    if j["outliers"]:
        book.text(ws, r, 1, "outliers left out of the effect search (likelihood-ratio test of one record, "
                            "Bonferroni over the records)")
        r += 1
        book.header(ws, r, 1, ["id", "step", "df", "residual_um", "z", "p_adjusted"])
        ws.column_dimensions["D"].width = max(ws.column_dimensions["D"].width or 0, 12)
        for o in j["outliers"]:
            r += 1
            book.text(ws, r, 1, o["id"])
            for k, key in enumerate(("step", "df", "residual_um", "z", "p_adjusted")):
                ws.cell(row=r, column=2 + k).value = o[key]
                ws.cell(row=r, column=2 + k).number_format = {"p_adjusted": "0.00E+00", "step": "0",
                                                              "df": "0"}.get(key, "0.000")
        r += 1
    r += 1
    for s, step in enumerate(j["steps"], start=1):
        book.text(ws, r, 1, f"step {s}: {len(step)} candidates tested (Bonferroni factor {len(step)})")
        r += 1
        book.header(ws, r, 1, ["name", "df", "delta_chi2", "p_value", "p_adjusted"])
        for item in step:
            r += 1
            book.text(ws, r, 1, item["name"])
            for k, key in enumerate(("df", "delta_chi2", "p_value", "p_adjusted")):
                ws.cell(row=r, column=2 + k).value = item[key]
                ws.cell(row=r, column=2 + k).number_format = _CANDIDATE_FORMATS[key]
        r += 2


def _groups(book: Book, diag: Diagnosis) -> None:
    ws = book.sheet("Groups")
    book.text(ws, 1, 1, "Chi-square of the records of every group (docs/recordings.md section 3.2), flagged when p < "
                        "alpha / number of groups")
    cols = ["by", "group", "records", "chi2", "dof", "p_value", "mean_z", "rms_z", "flagged"]
    book.header(ws, 2, 1, cols)
    for r, g in enumerate(diag.groups, start=3):
        book.text(ws, r, 1, g["by"])
        book.text(ws, r, 2, g["group"])
        for k, key in enumerate(("records", "chi2", "dof", "p_value", "mean_z", "rms_z")):
            ws.cell(row=r, column=3 + k).value = g[key]
        book.text(ws, r, 9, "yes" if g["flagged"] else "no")
    ws.column_dimensions["B"].width = 22


def _display_unit(unit: str) -> str:
    """A unit as the workbooks spell it (µm, µrad); diagnosis.json keeps the contract's um, urad (docs/recordings.md)."""
    return unit.replace("um", "µm").replace("urad", "µrad").replace("µrµm", "µrad") if unit != "1" else unit


def _results(book: Book, diag: Diagnosis, gls: dict, inputs: dict) -> list[dict]:
    """The Results sheet; returns its rows' values (the core's numbers, as in diagnosis.json) for
    the cached values.  A periodic error's period row is the scan's period (Inputs) plus the
    refit's step for it."""
    st = gls["stats"]
    js = diag.to_json()
    rows, cached = [], []
    for key, unit in (("chi2_before", "1"), ("dof_before", "1"), ("p_before", "1"), ("chi2_after", "1"),
                      ("dof_after", "1"), ("rms_before_um", "µm"), ("rms_after_um", "µm"),
                      ("p_targeted", "1"), ("p_after", "1")):
        rows.append([key, Formula(f"={st[key]}"), "", unit])
        cached.append({"value": float(js[key] if js[key] is not None else 1.0)})
    if diag.noise_scale:
        rows.append(["noise_scale", Formula(f"={st['noise_scale']}"), Formula(f"={st['u_noise_scale']}"), "1"])
        cached.append({"value": float(js["noise_scale"]["estimate"]), "u": float(js["noise_scale"]["u"])})
    for j, (e, l) in enumerate(diag.sel_labels):
        if e == "alignment":
            continue
        b = gls["b"].cell(j, 0)
        u = cell(gls["b_row"] + j, gls["u_col"], "GLS")
        u_value = float(math.sqrt(max(diag.cov_beta[j, j], 0.0)))
        if e in fx.PERIODIC and l == "period_mm":
            period = inputs["periodic"][e][0]
            rows.append([f"{e} {l}", Formula(f"={period}+{b}"), Formula(f"={u}"), "mm"])
            cached.append({"value": float(effect_estimates(diag, e)["period_mm"]), "u": u_value})
            continue
        rows.append([e if l == e else f"{e} {l}", Formula(f"={b}"), Formula(f"={u}"),
                     "µm" if e == "outlier" else _display_unit(fx.BY_NAME[e].unit)])
        cached.append({"value": float(diag.beta[j]), "u": u_value})
    ws = book.results(["quantity", "value", "u", "unit"], rows, [
        "chi2_before ... rms_after_um as in diagnosis.json; then one row per estimated effect parameter",
        "in the row's unit", "standard uncertainty, in the row's unit",
        "unit of value and u (diagnosis.json spells µm as um, µrad as urad: docs/recordings.md section 5)"])
    for r, row in enumerate(rows, start=2):
        # as a person reads them: p-values span decades (p_targeted 1e-10 showed as 0.000000)
        q = str(row[0])
        ws.cell(row=r, column=2).number_format = (FMT_SCI if q.startswith("p_") else "0" if q.startswith("dof")
                                                  else "0.00" if q.startswith("chi2") else FMT_UM)
        ws.cell(row=r, column=3).number_format = FMT_UM
    return cached


def _chart(book: Book, diag: Diagnosis, obs: dict) -> None:
    from openpyxl.chart import Reference

    ws = book.wb[obs["sheet"]]
    ci = obs["ci"]
    r0, r1 = obs["rows"][0], obs["rows"][-1]
    if diag.prep.design.kind == "length":
        x, x_title = Reference(ws, min_col=ci["d_mm"], min_row=r0, max_row=r1), "d / mm"
    else:
        x, x_title = None, "coordinate row"
    series = [ChartSeries(title, x, Reference(ws, min_col=ci[key], min_row=r0, max_row=r1))
              for key, title in (("z", "before"), ("z_after", "after"))]
    # below the table (on its own printed page); "after" is drawn first so that LibreOffice, which
    # draws the first series on top, shows it over "before" (see Book.scatter)
    anchor_row = r1 + 3
    book.scatter(ws, f"A{anchor_row}", "Standardized residuals z before and after the refit",
                 x_title, "z", series[::-1], width=24, height=13, page=book)
    book.print_setup(ws, row_breaks=[anchor_row - 1])


# -- PNG plots -----------------------------------------------------------------------------------

def _plt():
    from ..workbook.plots import pyplot   # headless, '$' in record ids and groups taken literally

    return pyplot()


def revealing_quantities(diag: Diagnosis) -> list[tuple[str, np.ndarray, bool]]:
    """(label, value per observation row, categorical) of the quantities that reveal effects."""
    prep = diag.prep
    rec, D = prep.rec, prep.design
    rows = prep.obs_record
    out = []
    if D.kind == "length":
        out.append(("length d / mm", rec.reference_mm, False))
        from xlfuncs.locator.diagnose import direction_label
        out.append(("direction", np.array([direction_label(v) for v in D.na]), True))
        if D.N1 is not None:
            o = np.einsum("ij,ij->i", D.na, D.N1) * np.einsum("ij,ij->i", D.na, D.N2)
            out.append(("probing", np.where(o < -0.25, "bidirectional", np.where(o > 0.25, "unidirectional", "other")), True))
        if len(D.probe_ids) > 1:
            out.append(("probes", np.array([D.probe_ids[a] if a == b else f"{D.probe_ids[a]}-{D.probe_ids[b]}"
                                            for a, b in zip(D.k1, D.k2)]), True))
    else:
        r = np.linalg.norm(D.Y - D.c, axis=1)
        out.append(("distance from the centroid / mm", r, False))
        out.append(("axis", np.array(["xyz"[a] for a in prep.obs_axis]), True))
        if len(D.probe_ids) > 1:
            out.append(("probe", np.array([D.probe_ids[k] for k in D.k]), True))
    if D.T is not None:
        out.append(("temperature / °C", D.T, False))
    if D.t is not None:
        out.append(("time / h", D.t / 3600.0, False))
    # expand per observation row; drop quantities that do not vary (they reveal nothing)
    out = [(lab, (v[rows] if len(v) == rec.n and D.kind == "point" and lab != "axis" else v), cat)
           for lab, v, cat in out]
    return [(lab, v, cat) for lab, v, cat in out
            if (len(set(v.tolist())) > 1 if cat else float(np.ptp(v)) > 0)]


def _own_quantity(diag: Diagnosis, name: str) -> tuple[str, np.ndarray, bool]:
    """What shows a straightness (the ram coordinate of its carriage: the curve c2 P2 + c3 P3)
    or a reversal (the approach direction along its axis), per observation row."""
    D, rows = diag.prep.design, diag.prep.obs_record
    if name in fx.PERIODIC:             # the travel along its axis (lengths: the far end's)
        a = fx.AXES.index(name[-1])
        u = D.U2[:, a] if D.kind == "length" else D.U[rows, a]
        return (f"ram {name[-1]} / mm" + (" (end 2 of the length)" if D.kind == "length" else ""), u, False)
    if name in fx.STRAIGHTNESS:
        c = fx.CARRIAGE_AXIS[name[2]]
        u = 0.5 * (D.U1[:, c] + D.U2[:, c]) if D.kind == "length" else D.U[rows, c]
        return (f"ram {name[2].lower()} / mm" + (" (middle of the length)" if D.kind == "length" else ""), u, False)
    a = fx.AXES.index(name[-1])
    ax = name[-1]
    if D.kind == "length":
        w = fx.approach_sign(D.N2, a) - fx.approach_sign(D.N1, a)
        lab = np.where(w > 0, f"end 1 moving -{ax}, end 2 moving +{ax}",
                       np.where(w < 0, f"end 1 moving +{ax}, end 2 moving -{ax}", f"no reversal along {ax}"))
        return (f"probe motion along {ax} at the two ends", lab, True)
    w = fx.approach_sign(D.N, a)[rows]
    return (f"probe motion along {ax} when touching", np.where(w > 0, f"moving +{ax}", np.where(
        w < 0, f"moving -{ax}", f"across {ax}")), True)


def _periodic_values(diag: Diagnosis, name: str, t: np.ndarray) -> np.ndarray:
    """The fitted periodic error a sin + b cos of 2 pi (t - middle)/P at ram coordinates t (µm)."""
    e = effect_estimates(diag, name)
    a, b = (v or 0.0 for v in e["estimate"])
    w = fx.periodic_angle(diag.prep.design, fx.AXES.index(name[-1]), t, e["period_mm"])
    return a * np.sin(w) + b * np.cos(w)


def _periodic_curve(ax, diag: Diagnosis, name: str, x: np.ndarray) -> None:
    """The fitted a sin + b cos of the travel as a line."""
    t = np.linspace(float(np.min(x)), float(np.max(x)), 800)
    ax.plot(t, _periodic_values(diag, name, t), "-", lw=1.2, color="C1",
            label=f"fitted a sin + b cos, period {effect_estimates(diag, name)['period_mm']:.4g} mm")


def _scatter(ax, x, y, cat, **kw):
    if cat:
        cats = list(dict.fromkeys(x.tolist()))
        pos = np.array([cats.index(v) for v in x.tolist()], dtype=float)
        jitter = (np.random.default_rng(0).random(len(pos)) - 0.5) * 0.3
        ax.plot(pos + jitter, y, "o", ms=3, **kw)
        ax.set_xticks(range(len(cats)))
        ax.set_xticklabels(cats, rotation=45, ha="right", fontsize=7)
    else:
        ax.plot(x, y, "o", ms=3, **kw)


def write_plots(diag: Diagnosis, out_dir: Path) -> list[Path]:
    plt = _plt()
    out_dir = Path(out_dir)
    files = []
    n = len(diag.z_before)
    # 1. before/after
    fig, ax = plt.subplots(figsize=(8, 4), dpi=110)
    ax.plot(np.arange(n), diag.z_before, "o", ms=3, label=f"before (chi2/dof {diag.chi2_before / diag.dof_before:.2f})")
    ax.plot(np.arange(n), diag.z_after, "o", ms=3, label=f"after (chi2/dof {diag.chi2_after / max(diag.dof_after, 1):.2f})")
    for yv in (-2, 2):
        ax.axhline(yv, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("record" if diag.prep.design.kind == "length" else "coordinate row")
    ax.set_ylabel("standardized residual z")
    ax.set_title("Residuals against the simulation, before and after adding "
                 + (", ".join(diag.chosen) if diag.chosen else "nothing"), fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    p = out_dir / "residuals_before_after.png"
    fig.savefig(p)
    plt.close(fig)
    files.append(p)
    # 2. residuals against the revealing quantities
    qs = revealing_quantities(diag) or [("record", np.arange(n, dtype=float), False)]
    k = len(qs)
    ncol = 2 if k > 1 else 1
    nrow = math.ceil(k / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(5 * ncol, 3.2 * nrow), dpi=100, squeeze=False)
    for (lab, x, cat), ax in zip(qs, axes.flat):
        _scatter(ax, x, diag.z_before, cat, label="before")
        _scatter(ax, x, diag.z_after, cat, label="after", alpha=0.6)
        ax.set_xlabel(lab)
        ax.set_ylabel("z")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[k:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("Standardized residuals against the quantities that reveal effects", fontsize=10)
    fig.tight_layout()
    p = out_dir / "residuals_by_quantity.png"
    fig.savefig(p)
    plt.close(fig)
    files.append(p)
    # 3. one figure per chosen effect: partial residual against the revealing quantity and the column
    reveal = {"scale": "length d / mm", "scale_x": "direction", "scale_y": "direction", "scale_z": "direction",
              "squareness_xy": "direction", "squareness_xz": "direction", "squareness_yz": "direction",
              "thermal_expansion": "temperature / °C", "probe_radius": "probing", "probe_qualification": "probes",
              "scale_drift": "time / h", "offset_drift": "time / h"}
    qmap = {lab: (x, cat) for lab, x, cat in qs}
    for name in diag.chosen:
        rows = diag.effect_rows(name)
        f = diag.X_sel[:, rows] @ diag.beta[rows]
        partial = diag.resid_after + f
        want = reveal.get(name, "length d / mm" if diag.prep.design.kind == "length" else "distance from the centroid / mm")
        if want not in qmap:
            want = {"probing": "length d / mm", "probes": "probe"}.get(want, qs[0][0])
            want = want if want in qmap else qs[0][0]
        x, cat = qmap[want]
        own = name in fx.STRAIGHTNESS or name in fx.REVERSAL or name in fx.PERIODIC
        if own:   # section 7: its own revealing quantity
            want, x, cat = _own_quantity(diag, name)
            if diag.prep.design.kind == "point":      # only the coordinate the effect moves
                keep = diag.prep.obs_axis == fx.AXES.index((name[1] if name in fx.STRAIGHTNESS else name[-1]).lower())
                x, partial, f = x[keep], partial[keep], f[keep]
                rows_x = diag.X_sel[keep][:, rows]
            else:
                rows_x = diag.X_sel[:, rows]
        else:
            rows_x = diag.X_sel[:, rows]
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8), dpi=100)
        if name in fx.PERIODIC and diag.prep.design.kind == "length":
            # the error at end 2: the length's residual along the axis plus the fitted error at end 1
            D = diag.prep.design
            k = fx.AXES.index(name[-1])
            seen = np.abs(D.na[:, k]) > fx.APPROACH_MIN
            near = _periodic_values(diag, name, D.U1[:, k])
            _scatter(a1, x[seen], partial[seen] / D.na[seen, k] + near[seen], cat,
                     label="error at end 2: residual / n_a (other effects out) + fitted error at end 1")
        else:
            _scatter(a1, x, partial, cat, label="residual without the other effects")
            _scatter(a1, x, f, cat, label=f"fitted {name}", alpha=0.7)
        if name in fx.PERIODIC:
            _periodic_curve(a1, diag, name, x)
        a1.set_xlabel(want)
        a1.set_ylabel("µm")
        a1.grid(alpha=0.3)
        a1.legend(fontsize=7)
        s = rows_x
        xs = s[:, 0] if s.shape[1] == 1 else f / max(np.max(np.abs(f)), 1e-300)
        a2.plot(xs, partial, "o", ms=3)
        order = np.argsort(xs)
        a2.plot(xs[order], f[order], "-", lw=1.5, color="C1")
        a2.set_xlabel(f"sensitivity to {name}" if s.shape[1] == 1 else "fitted (normalized)")
        a2.set_ylabel("µm")
        a2.grid(alpha=0.3)
        fig.suptitle(f"{name}: {fx.BY_NAME[name].plain}", fontsize=10)
        fig.tight_layout()
        p = out_dir / f"effect_{name}.png"
        fig.savefig(p)
        plt.close(fig)
        files.append(p)
    return files
