"""The diagnosis workbook (``cmmwb diagnose``, ``docs/recordings.md`` section 3).

Sheets: Instructions, Inputs (alpha, the simulation's parameters, probes, initial alignment of
point records), Records (the recordings as editable inputs, residuals, standardized residuals, the
sensitivity columns of the chosen effects as native formulas of the record cells, residuals after
the refit, chart before/after), Points + Coords (point records: one row per coordinate), Cov (the
simulation's covariance of the records, computed by the core from V_X), GLS (the generalized
least-squares normal equations over the alignment and the chosen columns: MINVERSE/MMULT),
Candidates (the search log of the core), Groups (chi-square per group of records), Results.

This module writes the workbook and its Instructions, Inputs, Candidates, Groups and Results
sheets; :mod:`.records` the record sheets, :mod:`.formulas` an effect's sensitivity as formula
text (one entry per family of effects), :mod:`.gls` the covariance and normal-equation sheets,
:mod:`.plots` the PNG figures.

Large or rank-deficient cases (more than ``NATIVE_MAX_OBS`` residuals, or a covariance without a
Cholesky factor) carry the whitened residual and columns W r, W X (W C W^T = I, computed by the
core) instead of Cov and its inverse; the normal equations stay native.
"""

from __future__ import annotations

import math
from pathlib import Path

from cmmwb.xlfuncs.locator import effects as fx
from cmmwb.xlfuncs.locator.diagnose import Diagnosis, effect_estimates
from cmmwb.xlfuncs.model.hyperparameters import in_use
from cmmwb.xlfuncs.pointcloud import Parameters

from ..workbook.book import Book, ChartSeries, Formula
from ..workbook.pagesetup import LINE_PT, wrapped_lines
from ..workbook.styles import FMT_SCI, FMT_UM
from ..workbook.xlref import Block, cell
from .gls import fill_after, gls_sheets
from .page import write_page
from .records import FOOTER_PT, RECORDS_SCALE, display_unit, length_records, point_records

NATIVE_MAX_OBS = 160
#: a hyper-parameter or a probe offset as typed (0.2, 200, -50), never in General's 12 digits
FMT_PARAM = "0.0###"


def param_unit(key: str) -> str:
    """The unit of a hyper-parameter, from its name (sigma_R_um -> µm; lambda_P has none)."""
    tail = key.rsplit("_", 1)[-1]
    return {"um": "µm", "urad": "µrad", "ppm": "ppm", "mm": "mm"}.get(tail, "1")


def write_book(diag: Diagnosis, path: Path, *, title_extra: str = "", params: Parameters | None = None,
               source: str = "", provenance: dict | None = None) -> Path:
    prep = diag.prep
    D = prep.design
    book = Book("diagnose", "diagnosis", "Mismatch locator — recordings against the simulation"
                + (f" ({title_extra})" if title_extra else ""))
    book.footer_pt = 11      # the sheets print at 73 % and more: footers of 8 pt and more
    native = prep.C.shape[0] <= NATIVE_MAX_OBS and diag.whitener.mode == "cholesky"
    _instructions(book, diag, native, source)
    inputs = inputs_sheet(book, diag, params)
    if D.kind == "length":
        rows, obs = length_records(book, diag, inputs)
    else:
        rows, obs = point_records(book, diag, inputs)
    gls = gls_sheets(book, diag, obs, native)
    fill_after(book, diag, obs, gls)
    _candidates(book, diag)
    _groups(book, diag)
    cached, results_rows = _results(book, diag, gls, inputs)
    _chart(book, diag, obs)
    write_page(book, diag, provenance, gls["stats"], results_rows, source or "the recordings")
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


def inputs_sheet(book: Book, diag: Diagnosis, params: Parameters | None) -> dict:
    """The Inputs sheet: alpha, the simulation's parameters, the probes and (point records) the
    initial alignment; returns the cells the record sheets refer to."""
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
        for key in in_use(params):
            book.text(ws, r, 1, key)
            book.number(ws, r, 2, getattr(params, key), fmt=FMT_PARAM, computed=True)
            book.text(ws, r, 3, param_unit(key))
            book.text(ws, r, 4, "simulation parameter; C computed from it by the core")
            r += 1
    ws.column_dimensions["A"].width = 18
    ws.column_dimensions["D"].width = 52
    r += 1
    book.text(ws, r, 1, "Probes (first = reference of probe_qualification)")
    r += 1
    book.header(ws, r, 1, ["probe", "px_mm", "py_mm", "pz_mm"])
    probe_cells = {}
    for k, probe in enumerate(prep.cloud.probes):
        r += 1
        book.text(ws, r, 1, probe.id)
        for c, v in enumerate(probe.offset_mm):
            book.number(ws, r, 2 + c, v, fmt=FMT_PARAM, computed=True)
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


#: the Candidates sheet's reason column (characters): the sheet prints landscape at 75 % or more
REASON_WIDTH = 40


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
        book.text(ws, r, 8, display_unit(fx.BY_NAME[c["name"]].unit))
        if c["reason"]:
            book.text(ws, r, 9, c["reason"], wrap=True)     # wrapped: the sheet prints on the page width
            ws.row_dimensions[r].height = LINE_PT * wrapped_lines(c["reason"], REASON_WIDTH) + 2
            book.align_top(ws, r, len(cols))
    ws.column_dimensions["A"].width = 20
    ws.column_dimensions["B"].width = 16
    for col in "EFG":
        ws.column_dimensions[col].width = 12
    ws.column_dimensions["I"].width = REASON_WIDTH
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
            ws.cell(row=r, column=3 + k).number_format = GROUP_FORMATS[key]
        book.text(ws, r, 9, "yes" if g["flagged"] else "no")
    ws.column_dimensions["B"].width = 22


#: the Groups sheet's numbers as a person reads them (General ran them together: 15 98.911538958)
GROUP_FORMATS = {"records": "0", "chi2": "0.00", "dof": "0", "p_value": "0.00E+00", "mean_z": "0.00",
                 "rms_z": "0.00"}


def _results(book: Book, diag: Diagnosis, gls: dict, inputs: dict) -> tuple[list[dict], dict[str, int]]:
    """The Results sheet; returns its rows' values (the core's numbers, as in diagnosis.json) for
    the cached values, and the row of each quantity.  A periodic error's period row is the scan's period (Inputs) plus the
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
                     "µm" if e == "outlier" else display_unit(fx.BY_NAME[e].unit)])
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
    return cached, {str(row[0]): r for r, row in enumerate(rows, start=2)}


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
    book.print_setup(ws, min_scale=RECORDS_SCALE, chart_row=anchor_row - 1, landscape=False, title_columns="A:A",
                     footer_pt=FOOTER_PT)
