"""The workbook of ``cmmwb calibrate``: the fitted hyper-parameters with u and their
identifiability, the records' standardized residuals under the fitted model, the REML profiles
(charts), the loop (effects fed back, u(d) and chi-square before and after) and the MPE check of
the fitted model (the pointcloud workbook's MPE sheet, native formulas of Forbes 2025 eqs. 33-36
on the fitted parameters)."""

from __future__ import annotations

import textwrap
from pathlib import Path

from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.model.hyperparameters import UNITS, in_use

from ..pointcloud.book import MPE_GRID_POINTS, write_mpe
from ..workbook.book import Book, ChartSeries, Formula
from ..workbook.pagesetup import LINE_PT, wrapped_lines
from ..workbook.xlref import cell
from .page import decision_block, write_page

NOTE_U = "standard uncertainty from the inverse observed information of the REML log-likelihood (delta method from log)"


def write_book(result: dict, path: Path, final: pc.Parameters, mpe: dict | None) -> Path:
    book = Book("calibrate", "calibration", "Calibration — the six factors' hyper-parameters from the machine's recordings")
    book.footer_pt = 11      # the sheets print at 73 % and more: footers of 8 pt and more
    _instructions(book, result)
    _fit(book, result)
    decided = _model(book, result, final, mpe)
    if mpe:
        assert MPE_GRID_POINTS == len(result["u_d"]["d_mm"])
        write_mpe(book, None)
    loop_rows = _loop(book, result, mpe is not None)
    _records(book, result)
    _profiles(book, result)
    cached, results_rows = _results(book, result, mpe is not None, decided)
    write_page(book, result, results_rows, loop_rows, decided)
    out = book.save(path)
    from ..workbook import cache

    cache.store(out, "calibrate", {"rows": cached})
    return out


def _instructions(book: Book, result: dict) -> None:
    book.para("What this workbook is", bold=True)
    book.para("The hyper-parameters of the six influence factors of Forbes 2025 (R, PQ, S, ET, ER, P; Tables 1 "
              "and 3) estimated from the machine's own recordings (" + ", ".join(result["recordings"]) + ") by "
              "restricted maximum likelihood, with the effects the locator named as fixed effects. Starting "
              f"values: {result['simulation']}.")
    book.gap()
    book.para("Sheets", bold=True)
    book.para("Fit: every hyper-parameter with its start, estimate, standard uncertainty u and status "
              "(estimated, not identifiable -- held at the task's value --, zero, off), the reason and the "
              "measurement that would identify it.",
              "Model: the fitted task's parameters (after the effects were fed back); the MPE sheet's native "
              "formulas use them.",
              "MPE: C(d) = K u(d)/(A + d/B) of the fitted model (Forbes 2025 eq. 36), native formulas.",
              "Loop: the effects fed back (" + result["feedback"] + "), the parameters they changed, chi-square "
              "before and after and u(d) before (the task) and after (the fitted task), with a chart.",
              "Records: residuals after the fixed effects, standardized by the fitted model.",
              "Profiles: the REML log-likelihood of each estimated hyper-parameter, the others re-optimized "
              "(the drop of 2 marks about the 95 % interval)"
              + (f"; {result['profiles_note']}." if result.get("profiles_note") else "."))
    book.gap()
    book.para("Summary", bold=True)
    book.para(result["summary"])


#: Fit's column widths (characters): the reason and the advice wrap in theirs, so that the sheet
#: prints on one landscape page width at about 75 % (text of 8 pt and more)
FIT_WIDTHS = (15, 6, 9, 10, 9, 7, 15, 34, 34)
def _fit(book: Book, result: dict) -> None:
    ws = book.sheet("Fit")
    cols = ["hyper_parameter", "unit", "start", "estimate", "u", "u_log", "status", "reason", "what would identify it"]
    book.header(ws, 1, 1, cols, [None, None, "the task's value", "REML estimate (the task's value when not estimated)",
                                 NOTE_U, "u of log(estimate)", None, None, None])
    for r, h in enumerate(result["hyper_parameters"], start=2):
        book.text(ws, r, 1, h["name"])
        book.text(ws, r, 2, h["unit"])
        book.number(ws, r, 3, h["start"], fmt="0.0000", computed=True)
        book.number(ws, r, 4, h["estimate"], fmt="0.0000", computed=True)
        if h["u"] is not None:
            book.number(ws, r, 5, h["u"], fmt="0.0000", computed=True)
            book.number(ws, r, 6, h["u_log"], fmt="0.000", computed=True)
        book.text(ws, r, 7, h["status"])
        book.text(ws, r, 8, h["reason"], wrap=True)
        book.text(ws, r, 9, h["advice"], wrap=True)
        # the row as high as its longest wrapped text, every cell at the top: a parameter's
        # name stands level with the first line of its reason, not under the previous one's
        lines = max(wrapped_lines(h["reason"], FIT_WIDTHS[7]), wrapped_lines(h["advice"], FIT_WIDTHS[8]))
        ws.row_dimensions[r].height = LINE_PT * lines + 2
        book.align_top(ws, r, len(cols))
    r = len(result["hyper_parameters"]) + 3
    for label, value, fmt in (("REML log-likelihood at the start", result["loglik_start"], "0.000"),
                              ("REML log-likelihood at the fit", result["loglik"], "0.000"),
                              ("chi2 r'Pr at the fit (1)", result["reml_chi2"], "0.000"),
                              ("dof (1)", result["reml_dof"], "0")):
        book.text(ws, r, 1, label)
        book.number(ws, r, 4, value, fmt=fmt, computed=True)
        r += 1
    ws.freeze_panes = "A2"
    book.print_setup(ws, landscape=True, fit_widths=False)
    for c, w in zip("ABCDEFGHI", FIT_WIDTHS):
        ws.column_dimensions[c].width = w


def _model(book: Book, result: dict, final: pc.Parameters, mpe: dict | None) -> bool:
    """The fitted task's parameters, the MPE statement and the MPE decision (when C_max has a u);
    returns whether the decision is there."""
    ws = book.sheet("Model")
    book.header(ws, 1, 1, ["parameter", "value", "unit"])
    r = 2
    for k in in_use(final):
        book.text(ws, r, 1, k)
        book.input(ws, r, 2, k, float(getattr(final, k)), lo=0.0, fmt="0.0000",
                   note="fitted task (calibration.json fitted_parameters): REML estimate, or the task's value "
                        "where not identifiable, after the effects were fed back")
        book.text(ws, r, 3, UNITS[k])
        r += 1
    if mpe:
        for k, unit in (("A_um", "µm"), ("B_mm", "mm"), ("K", "1"), ("P_mm", "mm"), ("L_max_mm", "mm")):
            book.text(ws, r, 1, k)
            book.input(ws, r, 2, k, float(mpe[k] if k != "P_mm" else result["u_d"]["P_mm"]), lo=0.0, fmt="0.0000",
                       note="MPE statement E = A + L/B (Forbes 2025 eq. 36; the task's [mpe] or --mpe)")
            book.text(ws, r, 3, unit)
            r += 1
    decided = False
    if mpe and result["mpe_check"] and result["mpe_check"]["fitted"]["decision"]["U"] is not None:
        fitted = result["mpe_check"]["fitted"]
        r = decision_block(book, ws, r + 1, fitted["decision"], fitted["u_C_max_from"])
        decided = True
    book.print_setup(ws)
    return decided


#: characters per line of a note on the Loop sheet (it prints landscape at full width)
NOTE_WIDTH = 110


def _loop(book: Book, result: dict, native: bool) -> dict[str, int]:
    """Effects, changes, notes, chi-square and the u(d) table on the landscape page width; the
    chart of u(d) on a page of its own after them.  Returns the row of each effect parameter
    ("file name label")."""
    from openpyxl.chart import Reference

    ws = book.sheet("Loop")
    book.text(ws, 1, 1, f"Effects fed back: {result['feedback']}")
    book.header(ws, 2, 1, ["effect", "file", "parameter", "estimate", "u", "unit"],
                [None, None, None, "GLS estimate at the fitted model, in the unit", "its standard uncertainty", None])
    r = 3
    rows = {}
    for e in result["effects"]:
        for lb, b, u in zip(e["labels"], e["estimate"], e["u"]):
            rows[f"{e['file']} {e['name']} {lb}"] = r
            book.text(ws, r, 1, e["name"])
            book.text(ws, r, 2, e["file"])
            book.text(ws, r, 3, lb)
            book.number(ws, r, 4, b, fmt="0.0000", computed=True)
            book.number(ws, r, 5, u, fmt="0.0000", computed=True)
            book.text(ws, r, 6, e["unit"].replace("um", "µm").replace("urad", "µrad"))
            r += 1
    r += 1
    book.header(ws, r, 1, ["hyper_parameter", "before", "after", "effects", "how"],
                [None, "in the parameter's unit", "in the parameter's unit", None, None])
    r += 1
    for c in result["changes"]:
        book.text(ws, r, 1, c["parameter"])
        book.number(ws, r, 2, c["before"], fmt="0.0000", computed=True)
        book.number(ws, r, 3, c["after"], fmt="0.0000", computed=True)
        book.text(ws, r, 4, ", ".join(c["effects"]), wrap=True)
        book.text(ws, r, 5, c["how"], wrap=True)
        lines = max(wrapped_lines(", ".join(c["effects"]), LOOP_WIDTHS[3]), wrapped_lines(c["how"], LOOP_WIDTHS[4]))
        ws.row_dimensions[r].height = LINE_PT * lines + 2
        book.align_top(ws, r, 5)
        r += 1
    for n in result["notes"]:
        for line in textwrap.wrap(n, NOTE_WIDTH, subsequent_indent="   "):
            book.text(ws, r, 1, line)
            r += 1
    r += 1
    ch = result["chi2"]
    book.header(ws, r, 1, ["chi2 (1)", "before", "after"],
                [None, "the task, records as measured", "the fitted task" + (
                    ", compensated records" if result["feedback"] == "compensate" else ", records as measured")])
    book.text(ws, r + 1, 1, "chi2")
    book.number(ws, r + 1, 2, ch["before"], fmt="0.00", computed=True)
    book.number(ws, r + 1, 3, ch["after"], fmt="0.00", computed=True)
    book.text(ws, r + 2, 1, "dof")
    book.number(ws, r + 2, 2, ch["dof_before"], fmt="0", computed=True)
    book.number(ws, r + 2, 3, ch["dof_after"], fmt="0", computed=True)
    r += 4
    first = r + 1
    ud = result["u_d"]
    unc = ud.get("uncompensated_um")
    book.header(ws, r, 1, ["d_mm", "u_before_um", "u_after_um"] + (["u_uncompensated_um"] if unc else []),
                ["grid 0 .. L_max_mm", "u(d) of the task, Forbes 2025 eq. (33) (core)",
                 "u(d) of the fitted task: MPE!C / K, eq. (33)" if native else "u(d) of the fitted task, eq. (33) (core)",
                 "u(d) of the same machine with the effects not corrected (carried as a factor), eq. (33) (core)"])
    for k, (d, ub, ua) in enumerate(zip(ud["d_mm"], ud["before_um"], ud["after_um"])):
        rr = first + k
        book.number(ws, rr, 1, d, fmt="0.0", computed=True)
        book.number(ws, rr, 2, ub, fmt="0.0000", computed=True)
        if native:
            book.formula(ws, rr, 3, f"={cell(2 + k, 3, 'MPE')}/K", fmt="0.0000")
        else:
            book.number(ws, rr, 3, ua, fmt="0.0000", computed=True)
        if unc:
            book.number(ws, rr, 4, unc[k], fmt="0.0000", computed=True)
    n = len(ud["d_mm"])
    x = Reference(ws, min_col=1, min_row=first, max_row=first + n - 1)
    anchor_row = first + n + 1
    book.scatter(ws, f"A{anchor_row}", "u(d) before (task) and after (fitted task)", "d / mm", "u / µm",
                 [ChartSeries(None, x, Reference(ws, min_col=c, min_row=first - 1, max_row=first + n - 1),
                              markers=False, title_from_data=True, bold=c == 3) for c in ((2, 3, 4) if unc else (2, 3))],
                 width=18, height=10, x_min=0, y_min=0, page=book)
    ws.freeze_panes = "A3"
    book.print_setup(ws, landscape=True, title_rows=None, fit_widths=False, row_breaks=[first - 1, anchor_row - 1])
    for c, w in zip("ABCDEF", LOOP_WIDTHS):
        ws.column_dimensions[c].width = w
    return rows


#: Loop's column widths (characters): landscape A4 at 100 %
LOOP_WIDTHS = (16, 14, 16, 22, 40, 8)


def _records(book: Book, result: dict) -> None:
    from openpyxl.chart import Reference

    ws = book.sheet("Records")
    book.header(ws, 1, 1, ["file", "observation", "residual_um", "u_um", "z"],
                [None, "record (lengths) or coordinate (points), in file order",
                 "residual after the fixed effects (GLS, fitted model)", "its standard uncertainty under the fitted model",
                 "standardized residual"])
    r = 2
    for f in result["residuals"]:
        for k, (e, u, z) in enumerate(zip(f["residual_um"], f["u_um"], f["z"])):
            book.text(ws, r, 1, f["file"])
            book.number(ws, r, 2, k + 1, fmt="0", computed=True)
            book.number(ws, r, 3, e, fmt="0.0000", computed=True)
            book.number(ws, r, 4, u, fmt="0.0000", computed=True)
            book.number(ws, r, 5, z, fmt="0.00", computed=True)
            r += 1
    breaks = []
    if r > 2:
        # below the table, on a page of its own
        x = Reference(ws, min_col=2, min_row=2, max_row=r - 1)
        anchor_row = r + 2
        book.scatter(ws, f"A{anchor_row}", "Standardized residuals under the fitted model", "observation", "z",
                     [ChartSeries("z", x, Reference(ws, min_col=5, min_row=2, max_row=r - 1))], width=18, height=9,
                     page=book)
        breaks.append(anchor_row - 1)
    ws.freeze_panes = "A2"
    book.print_setup(ws, row_breaks=breaks)


def _profiles(book: Book, result: dict) -> None:
    """One block per estimated hyper-parameter, stacked: the profile's values and its chart beside
    (portrait, two blocks a page)."""
    from openpyxl.chart import Reference

    if not result["profiles"]:
        return
    ws = book.sheet("Profiles")
    block_rows = 22
    for k, p in enumerate(result["profiles"]):
        top = 1 + block_rows * k
        # the name carries its unit (sigma_R_um, lambda_ET_mm; lambda_P has none)
        book.header(ws, top, 1, [p["name"], "delta_loglik", "minus_2"],
                    [f"{p['name']} in {p['unit']}", "REML log-likelihood minus its maximum, the others re-optimized",
                     "the drop of 2: about the 95 % interval"])
        for r, (v, dl) in enumerate(zip(p["value"], p["delta_loglik"]), start=top + 1):
            book.number(ws, r, 1, v, fmt="0.0000", computed=True)
            book.number(ws, r, 2, dl, fmt="0.000", computed=True)
            book.number(ws, r, 3, -2.0, fmt="0", computed=True)
        n = len(p["value"])
        x = Reference(ws, min_col=1, min_row=top + 1, max_row=top + n)
        # the drop of 2 in red and bold: a grey line lay on the grid line at -2, invisible
        book.scatter(ws, f"E{top}", f"REML profile of {p['name']}", f"{p['name']} / {p['unit']}",
                     "log-likelihood - max",
                     [ChartSeries("profile", x, Reference(ws, min_col=2, min_row=top + 1, max_row=top + n),
                                  markers=True),
                      ChartSeries("-2 (about 95 %)", x, Reference(ws, min_col=3, min_row=top + 1, max_row=top + n),
                                  markers=False, colour="C00000", dash="solid", bold=True)], width=9.5, height=8.5)
    per_page = 2
    book.print_setup(ws, landscape=False, title_rows=None, fit_widths=False,
                     row_breaks=[1 + block_rows * k for k in range(per_page, len(result["profiles"]), per_page)])
    for c, w in zip("ABCD", (12, 12, 8, 1)):
        ws.column_dimensions[c].width = w


def _results(book: Book, result: dict, native: bool, decided: bool) -> tuple[list[dict], dict[str, int]]:
    """The Results sheet; returns its rows' values (cached) and the row of each quantity."""
    rows, cached = [], []
    for h in result["hyper_parameters"]:
        if h["status"] != "estimated":
            continue
        rows.append([h["name"], h["estimate"], h["u"], h["unit"]])
        cached.append({"value": h["estimate"], "u": h["u"]})
    if native:
        m = result["mpe_check"]["fitted"]
        # u(C_max) of the MPE decision (Model sheet), the core's number
        rows.append(["C_max", Formula("=C_max", m["C_max"]),
                     Formula("=u_C_max", m["u_C_max"]) if decided else "", "1"])
        cached.append({"value": m["C_max"], **({"u": m["u_C_max"]} if decided else {})})
        rows.append(["d_at_max_mm", Formula("=d_at_max_mm", m["d_at_max_mm"]), "", "mm"])
        cached.append({"value": m["d_at_max_mm"]})
        rows.append(["margin", Formula("=1-C_max", m["margin"]), "", "1"])
        cached.append({"value": m["margin"]})
        last = 2 + len(result["u_d"]["d_mm"]) - 1
        rows.append(["u_after_at_L_max_um", Formula(f"={cell(last, 3, 'MPE')}/K", result["u_d"]["after_um"][-1]),
                     "", "µm"])
        cached.append({"value": result["u_d"]["after_um"][-1]})
    ws = book.results(["quantity", "value", "u", "unit"], rows,
                      ["estimated hyper-parameters (calibration.json), then the MPE check of the fitted model",
                       "in the row's unit", "standard uncertainty", "unit"])
    # as a person reads them (GUM 7.2.6): u to two significant digits, the value to the same
    # decimal place; the cells keep full precision
    fixed = {"C_max": "0.000", "d_at_max_mm": "0.0", "margin": "0.000", "u_after_at_L_max_um": "0.000"}
    for r, (row, c) in enumerate(zip(rows, cached), start=2):
        u = c.get("u")
        if isinstance(u, float) and u > 0:
            fmt = decimals_format(u)
            ws.cell(row=r, column=2).number_format = fmt
            ws.cell(row=r, column=3).number_format = fmt
        else:
            ws.cell(row=r, column=2).number_format = fixed.get(str(row[0]), "0.0000")
    return cached, {str(row[0]): r for r, row in enumerate(rows, start=2)}


def decimals_format(u: float) -> str:
    """The display format of a value and its u: u to two significant digits (GUM 7.2.6)."""
    import math

    decimals = max(0, 1 - math.floor(math.log10(u)))
    return "0." + "0" * decimals if decimals else "0"
