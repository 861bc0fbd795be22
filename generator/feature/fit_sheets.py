"""The fit chain of the ``feature`` workbook (Forbes 2022): ``Fit`` (the fitted frame and shape,
values computed by xlfuncs.features.fit), ``Local`` (weights, the points in the solution frame),
``J`` (residuals, the Jacobian, sections 4-8), ``H`` (H = J^T W J, its inverse, the Gauss-Newton
step), ``G_A_D`` (eq. (12)) and ``G_A_X`` (eq. (8)), as native formulas."""

from __future__ import annotations

from ..workbook.book import Book
from ..workbook.styles import FMT_SCI
from ..workbook.xlref import Block, cell
from .task import Task

FMT = "0.000000000"


SMALL = FMT_SCI


def feature_label(f) -> str:
    return "circle (in space)" if f.kind == "circle_space" else f.element


# -- the fit (values) -------------------------------------------------------------------------

def write_fit(book: Book, f, task: Task) -> dict:
    ws = book.sheet("Fit")
    book.text(ws, 1, 1, f"Fitted {feature_label(f)}: values computed by xlfuncs.features.fit "
                        f"(Gauss-Newton, {f.iterations} iterations) -- not formulas",
              font=None)
    note = ("Computed by cmmwb's core (xlfuncs.features.fit): the least-squares orthogonal "
            "distance fit of Forbes 2022 eq. (7)/(11) by Gauss-Newton. An iteration has no native "
            "formula; the 'H' sheet shows the next Gauss-Newton step, 0 at the solution.")
    book.text(ws, 3, 1, "origin_mm")
    for a in range(3):
        book.text(ws, 2, 2 + a, "xyz"[a])
        c = book.number(ws, 3, 2 + a, f.origin_mm[a], fmt=FMT, computed=True)
    book.note(ws.cell(row=3, column=2), note + " Origin of the solution frame: the locating "
                                               "point (centre for spheres and circles).")
    book.define("fit_origin", Block("Fit", 3, 2, 1, 3).ref)
    book.text(ws, 4, 1, "R: columns = frame x, y, z axes (z = element axis / normal)")
    for a in range(3):
        book.text(ws, 5 + a, 1, f"R row {'xyz'[a]}")
        for b in range(3):
            book.number(ws, 5 + a, 2 + b, f.R[a, b], fmt=FMT, computed=True)
    book.note(ws.cell(row=5, column=2), note + " Rotation of the solution frame: local "
                                               "coordinates P = (X - origin) R.")
    book.define("fit_R", Block("Fit", 5, 2, 3, 3).ref)
    refs = {"origin": Block("Fit", 3, 2, 1, 3), "R": Block("Fit", 5, 2, 3, 3)}
    r = 9
    for name, value, label in (("fit_r0", f.shape[0] if f.shape else None, "r0_mm"),
                               ("fit_phi", f.shape[1] if len(f.shape) > 1 else None, "phi_rad")):
        if value is None:
            continue
        book.text(ws, r, 1, label)
        book.number(ws, r, 2, value, fmt=FMT, computed=True)
        book.note(ws.cell(row=r, column=2), note)
        book.define(name, cell(r, 2, "Fit"))
        refs[name] = cell(r, 2, "Fit")
        r += 1
    r += 1
    for label, value in (("element", feature_label(f)), ("points m", f.m),
                         ("residuals per point k", f.k),
                         ("iterations", f.iterations),
                         ("rms residual (mm)", f.rms_mm),
                         ("circle plane", f.circle_plane or "")):
        if label == "circle plane" and not f.circle_plane:
            continue
        book.text(ws, r, 1, label)
        if isinstance(value, str):
            book.text(ws, r, 2, value)
        else:  # numbers as numbers: the rms of an exact fit is rounding noise, not text to compare
            book.number(ws, r, 2, value, fmt="0" if isinstance(value, int) else FMT_SCI, computed=True)
        r += 1
    ws.column_dimensions["A"].width = 28
    for c in "BCD":
        ws.column_dimensions[c].width = 18
    return refs


# -- local coordinates, Jacobian ----------------------------------------------------------------

def write_local(book: Book, f, task: Task, X: Block) -> dict:
    ws = book.sheet("Local")
    cols = ["id", "w", "x_loc_mm", "y_loc_mm", "z_loc_mm", "rho_mm", "c", "s"]
    notes = ["point id (Points)", "weight w_i of Forbes 2022 eq. (11) (W = diag(w_i^2), eq. (12))",
             "P = (X - origin) R: the points in the frame in which the element is in standard "
             "position (axis along z, locating point at the origin)", None, None,
             "distance from the frame z axis (sphere: from the centre)", "cos(theta) = x/rho",
             "sin(theta) = y/rho"]
    book.header(ws, 1, 1, cols, notes)
    m = f.m
    for i in range(m):
        book.text(ws, 2 + i, 1, task.cloud.labels[i])
        book.number(ws, 2 + i, 2, f.weights[i], fmt="General")
    P = Block("Local", 2, 3, m, 3)
    book.array(P, f"=MMULT({X.ref}-fit_origin,fit_R)", fmt=FMT,
               note="P = (X - origin) R, one row per point (Forbes 2022 section 3: the data "
                    "transformed so that the element is in standard position)")
    needs_rho = f.kind not in ("plane", "line")
    for i in range(m):
        r = 2 + i
        x, y, z = (cell(r, 3 + a) for a in range(3))
        if needs_rho:
            rho = f"SQRT({x}^2+{y}^2+{z}^2)" if f.kind == "sphere" else f"SQRT({x}^2+{y}^2)"
            book.formula(ws, r, 6, f"={rho}", fmt=FMT)
            book.formula(ws, r, 7, f"={x}/{cell(r, 6)}", fmt=FMT)
            book.formula(ws, r, 8, f"={y}/{cell(r, 6)}", fmt=FMT)
    ws.freeze_panes = "C2"
    return {"P": P, "w": Block("Local", 2, 2, m, 1)}


def _residual_rows(kind: str, x, y, z, rho, c, s):
    """(residual label, d formula, J formulas, local normal formulas) per residual of a point.
    Numbers are returned as floats (written as constants), formulas as strings."""
    if kind == "plane":
        return [("d", z, [-1.0, f"-{y}", x], [0.0, 0.0, 1.0])]
    if kind == "line":
        return [("d_x", x, [-1.0, 0.0, 0.0, f"-{z}"], [1.0, 0.0, 0.0]),
                ("d_y", y, [0.0, -1.0, z, 0.0], [0.0, 1.0, 0.0])]
    if kind == "sphere":
        nx, ny, nz = f"{x}/{rho}", f"{y}/{rho}", f"{z}/{rho}"
        return [("d", f"{rho}-fit_r0", [f"-({nx})", f"-({ny})", f"-({nz})", -1.0], [nx, ny, nz])]
    if kind == "circle":
        return [("d", f"{rho}-fit_r0", [f"-{c}", f"-{s}", -1.0], [c, s, 0.0])]
    if kind == "cylinder":
        return [("d", f"{rho}-fit_r0", [f"-{c}", f"-{s}", f"{z}*{s}", f"-({z}*{c})", -1.0],
                 [c, s, 0.0])]
    if kind == "circle_space":
        return [("d_axial", z, [0.0, 0.0, -1.0, f"-{y}", x, 0.0], [0.0, 0.0, 1.0]),
                ("d_radial", f"{rho}-fit_r0",
                 [f"-{c}", f"-{s}", 0.0, f"{z}*{s}", f"-({z}*{c})", -1.0], [c, s, 0.0])]
    if kind == "cone":
        cp, sp = "COS(fit_phi)", "SIN(fit_phi)"
        dC = f"({rho}-fit_r0)"
        return [("d", f"{cp}*{dC}+{sp}*{z}",
                 [f"-({cp}*{c})", f"-({cp}*{s})", f"{cp}*{z}*{s}-{sp}*{y}",
                  f"{sp}*{x}-{cp}*{z}*{c}", f"-{cp}", f"{cp}*{z}-{sp}*{dC}"],
                 [f"{cp}*{c}", f"{cp}*{s}", sp])]
    raise ValueError(kind)


J_NOTES = {
    "plane": "Forbes 2022 section 6: d = z (standard position), J = (-1, -y, x) for (z_A, rot_x, rot_y)",
    "line": "line in space: offsets d_x = x, d_y = y from the z axis; J rows (-1, 0, 0, -z), (0, -1, z, 0)",
    "sphere": "Forbes 2022 section 5: d = r_i - r0, J = -[n_i^T, 1]",
    "circle": "Forbes 2022 section 4: d = r_i - r0, J = -[n_i^T, 1]",
    "cylinder": "Forbes 2022 section 7: d = rho - r0, J = -[cos, sin, -z sin, z cos, 1]",
    "circle_space": "circle in space: axial residual z (J = (0,0,-1,-y,x,0)) and radial residual "
                    "rho - r0 (J = -[cos, sin, 0, -z sin, z cos, 1])",
    "cone": "Forbes 2022 section 8, eq. (26): d = cos(phi) d_C + sin(phi) d_P; J = [-cos(phi) cos, "
            "-cos(phi) sin, w sin, -w cos, -cos(phi), z/cos(phi)] on the cone, w = z/cos(phi) - r0 sin(phi)",
}


def _put(book: Book, ws, r: int, c: int, v, fmt=FMT):
    if isinstance(v, float):
        ws.cell(row=r, column=c).value = v
    else:
        book.formula(ws, r, c, f"={v}", fmt=fmt)


def write_jacobian(book: Book, f, local: dict, labels) -> dict:
    ws = book.sheet("J")
    n, k, m = f.n, f.k, f.m
    cols = ["point", "residual", "w2", "d_mm"] + [f"J_{nm}" for nm in f.local_names] + \
           ["nl_x", "nl_y", "nl_z", "n_x", "n_y", "n_z"]
    notes = [None, None, "W = diag(w_i^2), Forbes 2022 eq. (12)", "signed orthogonal distance "
             "(residual) at the fitted values, eq. (7)"] + \
            [J_NOTES[f.kind]] + [None] * (n - 1) + \
            ["unit normal of the residual in the frame"] + [None] * 2 + \
            ["normal in machine coordinates, n = R nl: the columns of N in G_A|X = G_A|D N^T (eq. (8))"] + [None] * 2
    book.header(ws, 1, 1, cols, notes)
    c0 = 5
    for i in range(m):
        lr = 2 + i
        x, y, z = (cell(lr, 3 + a, "Local") for a in range(3))
        rho, c, s = (cell(lr, 6 + a, "Local") for a in range(3))
        for j, (lab, d, Jrow, nl) in enumerate(_residual_rows(f.kind, x, y, z, rho, c, s)):
            r = 2 + k * i + j
            book.text(ws, r, 1, labels[i])
            book.text(ws, r, 2, lab)
            book.formula(ws, r, 3, f"={cell(lr, 2, 'Local')}^2", fmt="General")
            _put(book, ws, r, 4, d, fmt=SMALL)
            for p, v in enumerate(Jrow):
                _put(book, ws, r, c0 + p, v)
            for a, v in enumerate(nl):
                _put(book, ws, r, c0 + n + a, v)
            nlb = Block("J", r, c0 + n, 1, 3)
            for a in range(3):
                book.formula(ws, r, c0 + n + 3 + a,
                             f"=SUMPRODUCT({Block('Fit', 5 + a, 2, 1, 3).ref},{nlb.local})")
    ws.freeze_panes = "C2"
    km = k * m
    return {"J": Block("J", 2, c0, km, n), "w2": Block("J", 2, 3, km, 1),
            "d": Block("J", 2, 4, km, 1), "N": Block("J", 2, c0 + n + 3, km, 3)}


# -- H, G ---------------------------------------------------------------------------------------

def matrix_labels(book, ws, r, c, rows, cols):
    for q, lab in enumerate(cols):
        book.text(ws, r - 1, c + q, lab)
    for q, lab in enumerate(rows):
        book.text(ws, r + q, c - 1, lab)


def write_H(book: Book, f, jac: dict, labels) -> dict:
    ws = book.sheet("H")
    n = f.n
    names = list(f.local_names)
    J, w2, d = jac["J"].ref, jac["w2"].ref, jac["d"].ref
    book.text(ws, 1, 1, "H = J^T W J (Forbes 2022 eqs. (10), (12))")
    H = Block("H", 3, 2, n, n)
    matrix_labels(book, ws, 3, 2, names, names)
    book.array(H, f"=MMULT(TRANSPOSE({J}),{J}*{w2})", fmt=SMALL,
               note="H = J^T W J, W = diag(w_i^2) (eq. (12)); for V_X = sigma_R^2 I and w = 1, "
                    "V_A = sigma_R^2 H^-1 (eq. (10))")
    r = 3 + n + 2
    book.text(ws, r - 2, 1, "H^-1 = MINVERSE(H)")
    Hi = Block("H", r, 2, n, n)
    matrix_labels(book, ws, r, 2, names, names)
    book.array(Hi, f"=MINVERSE({H.ref})", fmt=SMALL, note="(J^T W J)^-1")
    step = gn_step_block(n)
    r2 = step.row
    assert r2 == r + n + 2
    book.text(ws, r2 - 1, 1, "Gauss-Newton step from the fitted values: delta = -(J^T W J)^-1 "
                             "J^T W d (0 at the least-squares solution)")
    for q, lab in enumerate(names):
        book.text(ws, r2 + q, 1, lab)
    book.array(step, f"=-MMULT({Hi.ref},MMULT(TRANSPOSE({J}*{w2}),{d}))", fmt=SMALL,
               note="Optimality check (Forbes 2022 section 3: J^T d = 0 at the solution). A "
                    "non-zero step means the points or weights changed since the fit.")
    ws.column_dimensions["A"].width = 14
    # G_A|D^T
    wg = book.sheet("G_A_D")
    km = f.k * f.m
    book.text(wg, 1, 1, "G_A|D^T = -W J (J^T W J)^-1: row = residual, column = parameter "
                        "(Forbes 2022 eq. (12), transposed)")
    GDt = Block("G_A_D", 3, 2, km, n)
    for q, lab in enumerate(names):
        book.text(wg, 2, 2 + q, lab)
    for q in range(km):
        i, j = divmod(q, f.k)
        book.text(wg, 3 + q, 1, labels[i] + (f" ({j + 1})" if f.k > 1 else ""))
    book.array(GDt, f"=-MMULT({J}*{w2},{Hi.ref})", fmt=SMALL,
               note="G_A|D = -(J^T W J)^-1 J^T W (eq. (12)); shown transposed")
    wg.freeze_panes = "B3"
    return {"H": H, "Hinv": Hi, "GDt": GDt, "step": step}


def write_G(book: Book, f, jac: dict, hs: dict) -> Block:
    ws = book.sheet("G_A_X")
    n, k, m = f.n, f.k, f.m
    book.text(ws, 1, 1, "G_A|X^T = N G_A|D^T: row = coordinate x1, y1, z1, x2, ..., column = "
                        "parameter (Forbes 2022 eq. (8), transposed; unit: parameter unit per mm)")
    for q, lab in enumerate(f.local_names):
        book.text(ws, 2, 2 + q, lab)
    GDt, N = hs["GDt"], jac["N"]
    for i in range(m):
        for a in range(3):
            r = 3 + 3 * i + a
            book.text(ws, r, 1, f"{'xyz'[a]}{i + 1}")
            for p in range(n):
                terms = [f"{GDt.cell(k * i + j, p)}*{N.cell(k * i + j, a)}" for j in range(k)]
                book.formula(ws, r, 2 + p, "=" + "+".join(terms), fmt=SMALL)
    book.note(ws.cell(row=3, column=2), "G_A|X(p, 3i+a) = sum over the residuals r of point i of "
                                        "G_A|D(p, r) n_r(a): a shift of x_i along the fitted normal "
                                        "changes the residual by the same amount (eq. (8))")
    ws.freeze_panes = "B3"
    return Block("G_A_X", 3, 2, 3 * m, n)


def gn_step_block(n: int) -> Block:
    """The Gauss-Newton step on 'H' (n x 1)."""
    return Block("H", 3 + n + 2 + n + 2, 2, n, 1)
