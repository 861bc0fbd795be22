"""The workbook of a ``characteristic`` task.

Sheets: 'Features' (the least-squares features, values from the core), 'V_A' (the joint
covariance of all features' parameters, G V_X G^T, values from the core), 'Sensitivity' (one
row d c / d a per smooth characteristic, and per position's margin), 'Characteristics' (value,
u, tolerance, bonus, zone, margin), 'Results' (the contract's summary).

Live formulas where the characteristic is a smooth function of the features' parameters: its u is
SQRT(MMULT(MMULT(s, V_A), TRANSPOSE(s))) over the sensitivity row s and the joint V_A, the
bonus of a position at MMC/LMC follows the size and the size limit, the zone and the margin
follow the tolerance.  Form values and the zones of surfaces are maxima over points (least-
squares peak-to-valley, minimum zone): their value and u are grey core values with a note.
"""

from __future__ import annotations

from cmmwb.xlfuncs import characteristics as ch

from .. import __version__
from ..pointcloud.vx_sheets import explain_inputs, write_inputs, write_points
from ..workbook.book import Book, BookAdditions, Formula
from ..workbook.xlref import Block, cell

FMT_MM = "0.000000"
FMT_U = "0.0000"
FMT_S = "0.000E+00"
#: u in the display unit = SQRT(s V_A s^T) x U_FACTOR: V_A is written x 1e12 (mm^2 -> nm^2; the
#: `formulas` engine rounds constants to 15 decimal places, docs/engines.md), so lengths in µm
#: are nm / 1000 and angles in µrad are deg x 1e-6 x pi/180 x 1e6
VALUE_SCALE = 1e12
U_FACTOR = {"mm": 1e-3, "deg": 3.141592653589793 / 180}

CHAR_COLUMNS = ["characteristic", "type", "method", "value", "unit", "u", "u_unit", "nominal",
                "lsl", "usl", "tolerance_mm", "condition", "bonus_mm", "zone_mm", "margin_mm",
                "u_margin_um", "contact points"]
CHAR_NOTES = [
    None, "ISO 1101 / ASME Y14.5 characteristic", "form: LS = peak-to-valley of the residuals to "
    "the least-squares feature, MZ = minimum zone (Chebyshev); orientation: LS-oriented or turned "
    "to its minimum zone",
    "measured value, in 'unit' (grey: computed by the core)", "mm or deg",
    "standard uncertainty under V_X, in u_unit (a formula of 'Sensitivity' and 'V_A' where the "
    "characteristic is smooth; grey core value with a note where not)", "µm or µrad",
    "nominal value (drawing)", "lower limit (size, distance, angle)", "upper limit",
    "tolerance zone width, mm (form, orientation, position)", "material condition (RFS, MMC, LMC)",
    "bonus tolerance from the measured size, mm (ASME Y14.5-2018 5.8.1)",
    "tolerance + bonus, mm", "zone - value, mm (positive: inside the zone)",
    "u of the margin, µm (size and position correlated through V_X)",
    "the points that decide a form value or zone (the active set of its sensitivity)"]


def write_characteristic_book(task, results: dict, path, jf, res, V, additions: BookAdditions | None = None) -> None:
    book = Book("characteristic", task.name, f"Characteristics of a drawing — {task.name}")
    _instructions(book, task, jf, res)
    _, probe_rows = write_inputs(book, task.params, task.cloud)
    write_points(book, task.cloud, probe_rows)
    _write_features(book, jf)
    va = _write_V_A(book, jf, V)
    srows = _write_sensitivity(book, jf, res)
    crows = _write_characteristics(book, res, va, srows, task)
    _write_chart(book, res, crows)
    # the contract's Results: one complete row per characteristic (tolerance, bonus, zone and
    # margin, which not every characteristic has, are on 'Characteristics' and in the JSON)
    rows = [[r.name, r.spec.type, Formula(f"={cell(row, 4, 'Characteristics')}", c["value"]), r.unit,
             Formula(f"={cell(row, 6, 'Characteristics')}", c["u"]), r.u_unit]
            for r, row, c in zip(res, crows, results["characteristics"])]
    book.results(["name", "type", "value", "unit", "u", "u_unit"], rows,
                 notes=[None, None, "measured value in 'unit'", "mm or deg",
                        "standard uncertainty in u_unit", "um or urad"])
    book.save(path, additions)


def _instructions(book: Book, task, jf, res) -> None:
    book.para("What this workbook computes", bold=True)
    book.para(
        f"The characteristics of a drawing from {len(jf.fits)} least-squares features fitted to "
        f"{jf.m} points of one CMM, with their standard uncertainty under the point-cloud variance "
        "V_X of A. Forbes, Appl. Sci. 2025, 15, 271 (six influence factors, eq. (28)). Features: "
        "A. Forbes, Appl. Sci. 2022, 12, 2808 (G_A|X, eqs. (8), (12)); all features' sensitivity "
        "matrices stacked give the joint V_A = G V_X G^T ('V_A'), whose off-diagonal blocks are the "
        "correlations between features measured by one machine.",
        "A characteristic c is linearised in the features' parameters a (and, for form values and "
        "surface zones, in the coordinates of the points that decide them): u^2(c) = s V_A s^T for a "
        "smooth characteristic (size, distance, angle, position, orientation of an axis) -- a live "
        "formula of the row s on 'Sensitivity' -- and u^2 = s_X V_X s_X^T with the active-set "
        "sensitivity s_X for form and surface zones (grey core values: the value is a maximum "
        "over points, not a smooth function).")
    book.gap()
    book.para("How to read it", bold=True)
    book.para(
        "1. 'Characteristics' lists each characteristic: value, u (µm for lengths, µrad for "
        "angles), the tolerance carried from the task (decided on the 'Decision' sheet), "
        "for a position at MMC/LMC the bonus from the measured size (ASME Y14.5-2018 5.8.1), the "
        "zone (tolerance + bonus), the margin (zone - value) and its u, which includes the "
        "correlation of size and position through V_X.",
        "2. Yellow cells (tolerances, size limits) can be edited: bonus, zone and margin follow. "
        "The fit, V_A and the sensitivities are grey values computed by cmmwb's core "
        f"(cmmwb {__version__}); rebuild from the task file to change points or the CMM model "
        "(`cmmwb build`). The feature kind's workbook shows V_A = G V_X G^T of one feature as "
        "native formulas. 'Inputs' (the CMM model) and 'Points' are the task's inputs: edit them, "
        "then `cmmwb read THIS.xlsx --out TASK.toml` and `cmmwb build` recompute everything.",
        "3. Conventions (docs/characteristics.md): least-squares datum features; datum frame z into "
        "the material from the primary plane, x from the secondary; the size of a feature of size "
        "is its least-squares diameter; position and orientation of an axis are taken over the "
        "extent of its points; minimum zones are exact (iterated small-angle LPs).")
    if task.notes:
        book.para(*task.notes)
    explain_inputs(book)


def _write_chart(book: Book, res, crows) -> None:
    """'Chart': u of the length characteristics (µm), one bar each, from 'Characteristics'."""
    from openpyxl.chart import Reference

    ws = book.sheet("Chart")
    book.header(ws, 1, 1, ["characteristic", "u_um"],
                [None, "standard uncertainty, µm (from 'Characteristics')"])
    r = 2
    for x, row in zip(res, crows):
        if x.unit != "mm":
            continue
        book.text(ws, r, 1, x.name)
        book.formula(ws, r, 2, f"={cell(row, 6, 'Characteristics')}", fmt=FMT_U)
        r += 1
    if r == 2:
        return
    cats = Reference(ws, min_col=1, min_row=2, max_row=r - 1)
    vals = Reference(ws, min_col=2, min_row=1, max_row=r - 1)
    book.bars(ws, "D2", "u of each characteristic under V_X", "u (µm)", cats, [vals],
              height=max(7.5, 0.75 * (r - 2) + 3))
    book.print_setup(ws, landscape=True)


def _write_features(book: Book, jf) -> None:
    ws = book.sheet("Features")
    book.header(ws, 1, 1, ["feature", "type", "points", "rms_residual_um", "parameter", "value",
                           "unit"],
                [None, None, "number of points fitted", "rms of the residuals to the fit, µm",
                 "reported parameter (Forbes 2022 global parameters)", "fitted value (grey: core)",
                 "unit of the value"])
    r = 2
    for name, f in jf.fits.items():
        book.text(ws, r, 1, name)
        book.text(ws, r, 2, f.element)
        ws.cell(row=r, column=3).value = f.m
        book.number(ws, r, 4, f.rms_mm * 1e3, fmt=FMT_U, computed=True)
        for p, v in zip(f.names, f.values):
            book.text(ws, r, 5, p)
            book.number(ws, r, 6, float(v), fmt=FMT_MM, computed=True)
            book.text(ws, r, 7, "mm" if p.endswith("_mm") else ("rad" if p.endswith("_rad") else "1"))
            r += 1
        r += 1
    book.print_setup(ws)


def _write_V_A(book: Book, jf, V) -> Block:
    ws = book.sheet("V_A")
    VA = ch.joint_V_A(jf, V)["total"]
    n = jf.n
    book.text(ws, 1, 1, "V_A x 1e12 (nm², mm·rad x 1e12, rad² x 1e12): joint covariance of all "
                        "features' local parameters, G V_X G^T (Forbes 2025 sec. 5.6), by the core")
    for p, name in enumerate(jf.param_names):
        book.text(ws, 2, 2 + p, name)
        book.text(ws, 3 + p, 1, name)
        for q in range(n):
            book.number(ws, 3 + p, 2 + q, float(VA[p, q]) * VALUE_SCALE, fmt=FMT_S, computed=True)
    book.note(ws.cell(row=3, column=2),
              "Values computed by cmmwb's core: V_A = G V_X G^T with G the stacked G_A|X of all "
              "features (Forbes 2022 eq. (8)) and V_X the six-factor point-cloud variance "
              "(Forbes 2025 eq. (28)), times 1e12: nm² for two length parameters, mm·rad x 1e12, "
              "rad² x 1e12.")
    _widths(ws, n)
    ws.freeze_panes = "B3"
    book.print_setup(ws, matrix=(n + 2, n + 1),
                     caption="V_A: top-left corner printed; the full matrix is in the workbook")
    return Block("V_A", 3, 2, n, n)


def _widths(ws, n: int) -> None:
    """Matrix sheets: wide enough for -1.234E-05 and the parameter names (no ###)."""
    from ..workbook.xlref import col

    ws.column_dimensions["A"].width = 22
    for q in range(n):
        ws.column_dimensions[col(2 + q)].width = 15


def _write_sensitivity(book: Book, jf, res) -> dict:
    ws = book.sheet("Sensitivity")
    n = jf.n
    book.text(ws, 1, 1, "s = d c / d a: value unit (mm or deg) per parameter unit (mm or rad); "
                        "central differences through the features' geometry (core values)")
    book.text(ws, 2, 1, "characteristic")
    for p, name in enumerate(jf.param_names):
        book.text(ws, 2, 2 + p, name)
    rows = {}
    r = 3
    for x in res:
        for key, s in ((x.name, x.s_A if x.smooth else None),
                       (f"{x.name} margin", x.s_A_margin if (x.smooth and x.s_A_margin is not None)
                        else None)):
            if s is None:
                continue
            book.text(ws, r, 1, key)
            for q in range(n):
                book.number(ws, r, 2 + q, float(s[q]), fmt=FMT_S, computed=True)
            rows[key] = Block("Sensitivity", r, 2, 1, n)
            r += 1
    _widths(ws, n)
    ws.freeze_panes = "B3"
    book.print_setup(ws, matrix=(r - 1, n + 1),
                     caption="Sensitivity rows: left columns printed; all columns in the workbook")
    return rows


def _write_characteristics(book: Book, res, va: Block, srows: dict, task) -> list[int]:
    ws = book.sheet("Characteristics")
    book.header(ws, 1, 1, CHAR_COLUMNS, CHAR_NOTES)
    rowof = {}
    out = []
    for k, x in enumerate(res):
        r = 2 + k
        rowof[x.name] = r
        out.append(r)
    for k, x in enumerate(res):
        r = 2 + k
        c = x.spec
        book.text(ws, r, 1, x.name)
        book.text(ws, r, 2, c.type)
        book.text(ws, r, 3, c.method if c.type in ch.FORM_TYPES + ch.ORIENTATION_TYPES else "")
        book.number(ws, r, 4, x.value, fmt=FMT_MM, computed=True)
        if c.measured is not None:
            book.note(ws.cell(row=r, column=4),
                      f"Measured value given in the task ('measured', e.g. a QIF results file's), not computed "
                      f"from this task's points (they give {x.points_value:.6g}); the points give the "
                      "sensitivities and so u: read the task's notes for what they are (a stand-in part?).")
        book.text(ws, r, 5, x.unit)
        scale = U_FACTOR[x.unit]
        if x.smooth:
            s = srows[x.name]
            book.array(Block("Characteristics", r, 6, 1, 1),
                       f"=SQRT(MAX(0,MMULT(MMULT({s.ref},{va.ref}),TRANSPOSE({s.ref}))))*{scale!r}",
                       fmt=FMT_U)
        else:
            book.number(ws, r, 6, x.u, fmt=FMT_U, computed=True)
            book.note(ws.cell(row=r, column=6),
                      "Core value: u^2 = s_X V_X s_X^T with the active-set sensitivity s_X (the "
                      "contact points in the last column held fixed); the value is a maximum over "
                      "points, not smooth. Checked against a JCGM 101 Monte Carlo over V_X in "
                      "cmmwb's tests (docs/characteristics.md).")
        book.text(ws, r, 7, x.u_unit)
        for col, v in ((8, c.nominal), (9, c.lsl), (10, c.usl), (11, c.tolerance_mm)):
            if v is not None:
                book.number(ws, r, col, float(v), fmt="General")
        book.text(ws, r, 12, c.material_condition if c.type == "position" else "")
        if x.bonus_mm is not None:
            if c.material_condition == "RFS":
                book.formula(ws, r, 13, "=0", fmt=FMT_MM)
            else:
                s = rowof[c.size]
                mmc = c.material_condition == "MMC"
                lim_col = (9 if c.internal else 10) if mmc else (10 if c.internal else 9)
                sign = (1 if c.internal else -1) * (1 if mmc else -1)
                size = cell(s, 4)
                lim = cell(s, lim_col)
                expr = f"{size}-{lim}" if sign > 0 else f"{lim}-{size}"
                book.formula(ws, r, 13, f"=MAX(0,{expr})", fmt=FMT_MM,
                             note="ASME Y14.5-2018 5.8.1: bonus = departure of the measured "
                                  "(least-squares) size from its MMC/LMC limit, never negative")
        if x.zone_mm is not None:
            book.formula(ws, r, 14, f"={cell(r, 11)}+{cell(r, 13)}", fmt=FMT_MM)
            book.formula(ws, r, 15, f"={cell(r, 14)}-{cell(r, 4)}", fmt=FMT_MM)
            key = f"{x.name} margin"
            if key in srows:
                s = srows[key]
                book.array(Block("Characteristics", r, 16, 1, 1),
                           f"=SQRT(MAX(0,MMULT(MMULT({s.ref},{va.ref}),TRANSPOSE({s.ref}))))/1000",
                           fmt=FMT_U)
            else:
                book.number(ws, r, 16, x.u_margin_um, fmt=FMT_U, computed=True)
        book.text(ws, r, 17, " ".join(task.cloud.labels[i] for i in x.active))
    ws.freeze_panes = "B2"
    book.print_setup(ws, landscape=True)
    return out
