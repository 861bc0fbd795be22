"""The point-cloud model laid out as live sheets: inputs, points, the long coordinate table and
the six V_X contributions of Forbes 2025 eq. (28) as native 3m x 3m array formulas.

Used by the ``pointcloud`` workbook and by any workbook that propagates V_X (fitted features).

Sheets written:

``Inputs``  the hyper-parameters (defined names = task keys), the probes table
``Points``  id, x, y, z (mm), outward normal, probe; derived probe offset p and ram position x - p
``Coords``  one row per coordinate (x1, y1, z1, x2, ...): the columns the V blocks broadcast over,
            the rows of G_X|S (eq. 11) and of the rotation sensitivity G_k (eq. 24)
``V_R`` ... ``V_P``, ``V_W`` and ``V_X``  the contributions and their sum (µm²); V_W is the part's
            thermal expansion (docs/workpiece.md), from the workpiece inputs on Inputs
"""

from __future__ import annotations

from dataclasses import dataclass

from cmmwb.xlfuncs.model.hyperparameters import FACTOR_RECORDS, HYPERPARAMETERS, PROBE_OVERRIDES, S_COLUMNS, in_table
from cmmwb.xlfuncs.model.workpiece import PREFIX
from cmmwb.xlfuncs.pointcloud import FACTORS, Parameters, PointCloud

from ..workbook.book import Book
from ..workbook.styles import FMT_COORD
from ..workbook.workpiece import U_EPS, write_workpiece_inputs
from ..workbook.xlref import Block, cell

# Workbook limit for native V_X formulas: 3m x 3m array formulas per factor.  Measured:
# m = 52 (156 x 156) recalculates in ~1 s per matrix in `formulas`; see bench/.
NATIVE_MAX_POINTS = 120

# the notes, units and factor titles of the Inputs and V sheets: the records' (xlfuncs.model.hyperparameters)
PARAM_NOTES = {h.name: h.note for h in HYPERPARAMETERS}
PARAM_UNITS = {h.name: h.unit for h in HYPERPARAMETERS}
FACTOR_TITLES = {f.label: f.title for f in FACTOR_RECORDS}


@dataclass
class VXLayout:
    """Where the point-cloud model lives in the workbook."""

    m: int
    X: Block          # m x 3 coordinates (Points)
    N: Block          # m x 3 normals (Points)
    V: dict           # factor -> Block (3m x 3m), plus "X" for the total
    probe_rows: dict  # probe index -> row on Inputs


def explain_inputs(book: Book) -> None:
    """The instruction sheet's paragraphs on cell colours (inherited defaults) and printing."""
    book.gap()
    book.para("Cell colours and printing", bold=True)
    inherits = ", ".join(PROBE_OVERRIDES[:-1]) + f" and {PROBE_OVERRIDES[-1]}"
    book.para(
        f"Yellow: an input you type. Green: an input that inherits a default by formula (a probe's {inherits} "
        f"on 'Inputs' are ={PROBE_OVERRIDES[0]} ... of the task-wide values); its note says what it inherits. "
        "Typing a number there overrides the default "
        "for that probe only and cuts the link. White: formulas. Grey: values computed by the core.",
        "Printing: every sheet is set up for A4, scaled to the page width, with the header row repeated; "
        "large matrix sheets (V_R ... V_X, GP_blocks) print their top-left corner only (the whole matrix "
        "stays in the workbook, the page header says so); charts "
        "print on their own page. `cmmwb build --pdf` prints the workbook to PDF with LibreOffice.")


def _name_safe(i: int) -> str:
    return f"probe{i + 1}"


def write_inputs(book: Book, params: Parameters, cloud: PointCloud, extra: list[tuple] = ()) -> tuple:
    """The Inputs sheet: named parameters, optional extra named inputs, the probes table."""
    ws = book.sheet("Inputs")
    book.header(ws, 1, 1, ["parameter", "value", "unit", "meaning"])
    r = 2
    for key in in_table("parameters"):
        book.text(ws, r, 1, key)
        book.input(ws, r, 2, key, getattr(params, key), lo=0.0, note=PARAM_NOTES[key])
        book.text(ws, r, 3, PARAM_UNITS[key])
        book.text(ws, r, 4, PARAM_NOTES[key])
        r += 1
    # the part's temperature, the factor W (its rows follow the hyper-parameters: one name/value range)
    r = write_workpiece_inputs(book, ws, r, cloud.workpiece, {k: getattr(params, k) for k in in_table("workpiece")})
    for key, value, unit, meaning, lo in extra:
        book.text(ws, r, 1, key)
        book.input(ws, r, 2, key, value, lo=lo, note=meaning)
        book.text(ws, r, 3, unit)
        book.text(ws, r, 4, meaning)
        r += 1
    ws.column_dimensions["A"].width = 16
    ws.column_dimensions["D"].width = 60
    r += 1
    book.text(ws, r, 1, "Probes (offset p_k = stylus tip centre from the probe-head reference point)",
              font=None)
    r += 1
    cols = ["probe", "px_mm", "py_mm", "pz_mm", *PROBE_OVERRIDES]
    book.header(ws, r, 1, cols)
    probe_rows = {}
    for k, p in enumerate(cloud.probes):
        r += 1
        probe_rows[k] = r
        book.text(ws, r, 1, p.id)
        for c, v in enumerate(p.offset_mm):
            book.input(ws, r, 2 + c, f"{_name_safe(k)}_p{'xyz'[c]}_mm", v)
        for c, key in enumerate(PROBE_OVERRIDES):
            own = getattr(p, key)
            name = f"{_name_safe(k)}_{key}"
            if own is None:
                book.default(ws, r, 5 + c, name, f"={key}", lo=0.0)   # green, with a note
            else:
                book.input(ws, r, 5 + c, name, own, lo=0.0, note="per-probe override")
    return ws, probe_rows


def write_points(book: Book, cloud: PointCloud, probe_rows: dict) -> tuple[Block, Block, Block]:
    """The Points sheet; returns the blocks of X (m x 3), N (m x 3) and U = X - p (m x 3)."""
    ws = book.sheet("Points")
    cols = ["id", "x_mm", "y_mm", "z_mm", "nx", "ny", "nz", "probe", "px_mm", "py_mm", "pz_mm",
            "ux_mm", "uy_mm", "uz_mm"]
    notes = [None] * 8 + ["probe offset p_k(i) (from Inputs)"] * 3 + \
            ["machine (ram) position x_i - p_k(i), Forbes 2025 section 5.3"] * 3
    book.header(ws, 1, 1, cols, notes)
    for i in range(cloud.m):
        r = i + 2
        k = int(cloud.probe_index[i])
        book.text(ws, r, 1, cloud.labels[i])
        for c in range(3):
            # mm, to 1 nm: General showed 11 digits and a sampled 0 as 6.12323399574E-16
            book.number(ws, r, 2 + c, cloud.X_mm[i, c], fmt=FMT_COORD)
            book.number(ws, r, 5 + c, cloud.N[i, c], fmt="0.000000")
        book.text(ws, r, 8, cloud.probes[k].id)
        for c in range(3):
            book.formula(ws, r, 9 + c, f"={cell(probe_rows[k], 2 + c, 'Inputs')}", fmt="General")
            book.formula(ws, r, 12 + c, f"={cell(r, 2 + c)}-{cell(r, 9 + c)}")
    ws.freeze_panes = "B2"
    m = cloud.m
    return Block("Points", 2, 2, m, 3), Block("Points", 2, 5, m, 3), Block("Points", 2, 12, m, 3)


COORD_COLS = ["coordinate", "point", "axis", "index", "probe_no", "ux_mm", "uy_mm", "uz_mm",
              "n_axis", "nx", "ny", "nz",
              "GS_aa", "GS_xx", "GS_yy", "GS_zz", "GS_xy", "GS_xz", "GS_yz",
              "GR_x", "GR_y", "GR_z", *PROBE_OVERRIDES, "w_mm"]


def write_coords(book: Book, cloud: PointCloud, probe_rows: dict) -> dict[str, Block]:
    """One row per coordinate x1, y1, z1, x2, ...: returns a column Block per name."""
    ws = book.sheet("Coords")
    book.header(ws, 1, 1, COORD_COLS)
    ci = {name: k + 1 for k, name in enumerate(COORD_COLS)}
    for i in range(cloud.m):
        k = int(cloud.probe_index[i])
        pr = probe_rows[k]
        prow = i + 2  # row on Points
        for a in range(3):
            r = 3 * i + a + 2
            book.text(ws, r, ci["coordinate"], f"{'xyz'[a]}{i + 1}")
            book.text(ws, r, ci["point"], cloud.labels[i])
            ws.cell(row=r, column=ci["axis"]).value = a + 1
            ws.cell(row=r, column=ci["index"]).value = 3 * i + a + 1
            ws.cell(row=r, column=ci["probe_no"]).value = k + 1
            for c, key in enumerate(("ux_mm", "uy_mm", "uz_mm")):
                book.formula(ws, r, ci[key], f"={cell(prow, 12 + c, 'Points')}")
            book.formula(ws, r, ci["n_axis"], f"={cell(prow, 5 + a, 'Points')}")
            for c, key in enumerate(("nx", "ny", "nz")):
                book.formula(ws, r, ci[key], f"={cell(prow, 5 + c, 'Points')}")
            ux, uy, uz = (cell(r, ci[k2]) for k2 in ("ux_mm", "uy_mm", "uz_mm"))
            # G(x_i - p) of Forbes 2025 eq. (11), row a
            gs = [[ux, ux, "0", "0", uy, uz, "0"], [uy, "0", uy, "0", "0", "0", uz],
                  [uz, "0", "0", uz, "0", "0", "0"]][a]
            for c, v in enumerate(gs):
                _ref_or_zero(book, ws, r, ci["GS_aa"] + c, v)
            px, py, pz = (cell(pr, 2 + c, "Inputs") for c in range(3))
            # G_k of Forbes 2025 eq. (24), row a
            gr = [["0", pz, f"-{py}"], [f"-{pz}", "0", px], [py, f"-{px}", "0"]][a]
            for c, v in enumerate(gr):
                _ref_or_zero(book, ws, r, ci["GR_x"] + c, v)
            for c, key in enumerate(PROBE_OVERRIDES):
                book.formula(ws, r, ci[key], f"={cell(pr, 5 + c, 'Inputs')}", fmt="General")
            # x_i - x0 of this coordinate: the part expands about the fixture point (docs/workpiece.md)
            book.formula(ws, r, ci["w_mm"], f"={cell(prow, 2 + a, 'Points')}-{PREFIX}fixture_{'xyz'[a]}_mm",
                         fmt="General")
    n3 = 3 * cloud.m
    ws.freeze_panes = "C2"
    return {name: Block("Coords", 2, ci[name], n3, 1) for name in COORD_COLS} | {
        "GS": Block("Coords", 2, ci["GS_aa"], n3, 7), "GR": Block("Coords", 2, ci["GR_x"], n3, 3)}


def _ref_or_zero(book: Book, ws, r: int, c: int, v: str) -> None:
    """Structural zeros of a sensitivity matrix are numbers, the rest references."""
    if v == "0":
        ws.cell(row=r, column=c).value = 0
    else:
        book.formula(ws, r, c, f"={v}", fmt="General")


def _t(b: Block) -> str:
    return f"TRANSPOSE({b.ref})"


def _sqdist(cols: list[Block]) -> str:
    return "+".join(f"({c.ref}-{_t(c)})^2" for c in cols)


def v_formulas(c: dict[str, Block], vb: Block) -> dict[str, str]:
    """Array formulas (3m x 3m, µm²) of the six contributions of eq. (28) and the part's W."""
    same_probe = f"({c['probe_no'].ref}={_t(c['probe_no'])})"
    same_axis = f"({c['axis'].ref}={_t(c['axis'])})"
    D2 = _sqdist([c["ux_mm"], c["uy_mm"], c["uz_mm"]])
    DN2 = _sqdist([c["nx"], c["ny"], c["nz"]])
    lam2 = f"({c['lambda_P'].ref}*{_t(c['lambda_P'])})"
    return {
        "R": f"=sigma_R_um^2*({c['index'].ref}={_t(c['index'])})",
        "PQ": f"={same_probe}*{same_axis}*{c['sigma_PQ_um'].ref}*{_t(c['sigma_PQ_um'])}",
        "S": f"=MMULT(MMULT({c['GS'].ref},{vb.ref}),TRANSPOSE({c['GS'].ref}))",
        # (lambda=0) keeps the exponent finite when the factor is switched off (sigma = 0)
        "ET": f"=sigma_ET_um^2*{same_axis}*EXP(-({D2})/(lambda_ET_mm^2+(lambda_ET_mm=0)))",
        "ER": f"=(sigma_ER_urad*0.001)^2*EXP(-({D2})/(lambda_ER_mm^2+(lambda_ER_mm=0)))"
              f"*MMULT({c['GR'].ref},TRANSPOSE({c['GR'].ref}))",
        "P": f"={same_probe}*{c['n_axis'].ref}*{_t(c['n_axis'])}*({c['sigma_P0_um'].ref}*{_t(c['sigma_P0_um'])}"
             f"+{c['sigma_P_um'].ref}*{_t(c['sigma_P_um'])}*EXP(-({DN2})/({lam2}+({lam2}=0))))",
        # docs/workpiece.md: u^2(eps) (x_i - x0)(x_j - x0)^T, u(eps) in ppm (1 ppm x 1 mm = 0.001 µm)
        "W": f"=({U_EPS}*0.001)^2*({c['w_mm'].ref}*{_t(c['w_mm'])})",
    }


def write_VB(book: Book) -> Block:
    """V_B of Forbes 2025 eq. (13) in (µm/mm)² on the Inputs sheet (right of the parameters)."""
    ws = book.wb["Inputs"]
    r0, c0 = 1, 7
    book.text(ws, r0, c0, "V_B, Forbes 2025 eq. (13), in (µm/mm)²: 1 µm/mm = 1000 ppm, so an entry "
              "is (sigma_ppm x 0.001)²")
    names = S_COLUMNS
    labels = ["b_aa", "b_xx", "b_yy", "b_zz", "b_xy", "b_xz", "b_yz"]
    for k, lab in enumerate(labels):
        book.text(ws, r0 + 1, c0 + 1 + k, lab)
        book.text(ws, r0 + 2 + k, c0, lab)
    for a in range(7):
        for b in range(7):
            if a == b:
                book.formula(ws, r0 + 2 + a, c0 + 1 + b, f"=({names[a]}*0.001)^2", fmt="0.00E+00")
            else:
                ws.cell(row=r0 + 2 + a, column=c0 + 1 + b).value = 0
    return Block("Inputs", r0 + 2, c0 + 1, 7, 7)


def write_V_sheets(book: Book, cloud: PointCloud, coords: dict[str, Block], vb: Block) -> dict[str, Block]:
    """One sheet per contribution plus V_X; each matrix at B2 with coordinate labels."""
    n3 = 3 * cloud.m
    out: dict[str, Block] = {}
    formulas = v_formulas(coords, vb)
    labels = [f"{'xyz'[a]}{i + 1}" for i in range(cloud.m) for a in range(3)]
    for f in (*FACTORS, "X"):
        ws = book.sheet(f"V_{f}")
        book.text(ws, 1, 1, "µm²")
        for k, lab in enumerate(labels):
            book.text(ws, 1, 2 + k, lab)
            book.text(ws, 2 + k, 1, lab)
        target = Block(ws.title, 2, 2, n3, n3)
        if f == "X":
            formula = "=" + "+".join(out[g].ref for g in FACTORS)
            note = "V_X = sum of the contributions, Forbes 2025 eq. (28), and the part's V_W (docs/workpiece.md)"
        else:
            formula = formulas[f]
            note = f"V_{f}: {FACTOR_TITLES[f]}"
        book.array(target, formula, note=note, fmt=None)  # formatting 3m x 3m cells costs seconds
        ws.freeze_panes = "B2"
        book.print_setup(ws, matrix=(n3, n3), caption=(
            f"{ws.title} (µm²): top-left corner of the {n3} x {n3} matrix; the whole matrix is in the "
            "workbook, not in the printout"))
        out[f] = target
    return out


def write_point_cloud_model(book: Book, cloud: PointCloud, params: Parameters,
                            extra_inputs: list[tuple] = ()) -> VXLayout:
    """Inputs, Points, Coords and the V sheets; returns where everything is."""
    _, probe_rows = write_inputs(book, params, cloud, list(extra_inputs))
    X, N, _U = write_points(book, cloud, probe_rows)
    coords = write_coords(book, cloud, probe_rows)
    vb = write_VB(book)
    V = write_V_sheets(book, cloud, coords, vb)
    return VXLayout(cloud.m, X, N, V, probe_rows)


def point_block(V: Block, i: int, j: int) -> Block:
    """The 3 x 3 block V_ij (0-based point indices) of a 3m x 3m matrix."""
    return V.sub(3 * i, 3 * j, 3, 3)
