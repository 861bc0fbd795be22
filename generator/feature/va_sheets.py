"""The ``V_A`` and ``Budget`` sheets of the ``feature`` workbook: T (reported <- local
parameters) and, per factor, V_A,f = G V_X,f G^T and T V_A,f T^T (Forbes 2025 section 5.6);
value, u and u per factor of each parameter, and the factor chart."""

from __future__ import annotations

from cmmwb.xlfuncs import pointcloud as pc

from .. import __version__
from ..pointcloud.large_book import LIVE
from ..pointcloud.vx_sheets import FACTOR_TITLES
from ..workbook.book import Book
from ..workbook.xlref import Block, cell
from .fit_sheets import FMT, SMALL, matrix_labels

#: core-computed V_A blocks are written x 1e12 (see write_V_A)
VALUE_SCALE = 1e12


# -- V_A per factor -----------------------------------------------------------------------------

def _T_entries(f) -> dict[tuple[int, int], str | float]:
    """T = d(reported)/d(local) as formulas of the frame rotation R (see xlfuncs.features)."""
    g = len(f.names)
    out: dict[tuple[int, int], str | float] = {}
    if f.kind in ("sphere", "circle"):
        for i in range(g):
            out[(i, i)] = 1.0
        return out
    ix = {nm: j for j, nm in enumerate(f.local_names)}

    def R(a, b):
        return cell(5 + a, 2 + b, "Fit")

    for b, ax in enumerate(("x_A_mm", "y_A_mm", "z_A_mm")):
        if ax in ix:
            for a in range(3):
                out[(a, ix[ax])] = R(a, b)
    for a in range(3):
        out[(3 + a, ix["rot_y_rad"])] = R(a, 0)
        out[(3 + a, ix["rot_x_rad"])] = f"-{R(a, 1)}"
    for extra in ("r0_mm", "phi_rad"):
        if extra in ix:
            out[(f.names.index(extra), ix[extra])] = 1.0
    return out


def v_a_layout(n: int, g: int) -> dict[str, tuple[Block, Block]]:
    """Where 'V_A' holds each factor's (paper, reported) covariance blocks."""
    first, span = 3 + g + 3, max(n, g) + 3
    return {fac: (Block("V_A", first + q * span, 2, n, n),
                  Block("V_A", first + q * span, 2 + n + 2, g, g))
            for q, fac in enumerate((*pc.FACTORS, "total"))}


def write_V_A(book: Book, f, unc, G: Block, V, method: str) -> dict:
    ws = book.sheet("V_A")
    n, g = f.n, len(f.names)
    names, lnames = list(f.names), list(f.local_names)
    book.text(ws, 1, 1, "T: reported parameters <- paper parameters (linear map at the fit; "
                        "reported covariance = T V_A T^T)")
    T = Block("V_A", 3, 2, g, n)
    matrix_labels(book, ws, 3, 2, names, lnames)
    ent = _T_entries(f)
    for a in range(g):
        for b in range(n):
            v = ent.get((a, b), 0.0)
            if isinstance(v, float):
                ws.cell(row=3 + a, column=2 + b).value = v
            else:
                book.formula(ws, 3 + a, 2 + b, f"={v}", fmt=FMT)
    book.note(ws.cell(row=3, column=2),
              "Locating point: R (dx_A, dy_A, dz_A); direction: R (rot_y, -rot_x, 0); r0, phi "
              "unchanged (xlfuncs.features, reported parameters)")
    out_local, out_glob, grey = {}, {}, {}
    Gt = G.ref
    blocks = [(1, 3 + g - 1)]
    for fac, (L, Gl) in v_a_layout(n, g).items():
        top = L.row
        blocks.append((top - 2, top + max(n, g) - 1))     # a factor's caption and its matrices, on one page
        book.text(ws, top - 2, 1, f"{fac}: V_A,{fac} paper parameters (left), reported T V_A T^T (right)"
                  if fac != "total" else "total: sum of the contributions (Forbes 2025 section 5.6; W the part's, docs/workpiece.md)")
        matrix_labels(book, ws, top, 2, lnames, lnames)
        matrix_labels(book, ws, top, 2 + n + 2, names, names)
        if fac == "total":
            book.array(L, "=" + "+".join(out_local[x].ref for x in pc.FACTORS), fmt=SMALL,
                       note="V_A = sum over the factors (Forbes 2025 section 5.6)")
        elif V is not None:
            book.array(L, f"=MMULT(MMULT(TRANSPOSE({Gt}),{V[fac].ref}),{Gt})*0.000001", fmt=SMALL,
                       note=f"V_A,{fac} = G_A|X V_{fac} G_A|X^T (µm² -> mm²: x 1e-6), "
                            "Forbes 2025 section 5.6")
        elif fac == "R":
            book.array(L, f"=sigma_R_um^2*MMULT(TRANSPOSE({Gt}),{Gt})*0.000001", fmt=SMALL,
                       note="V_A,R = sigma_R^2 G_A|X G_A|X^T (V_R = sigma_R^2 I, Forbes 2025 eq. (8))")
        else:
            # The core's values, scaled by 1e12 (mm^2 -> nm^2): the `formulas` engine rounds
            # numeric constants to 15 decimal places, which would cut 1e-8 mm^2 to 7 digits.
            Vv = unc.V_local[fac] * VALUE_SCALE
            vb = Block("V_A", top, 2 + n + 2 + g + 2, n, n)
            book.text(ws, top - 1, vb.column, f"V_A,{fac} x 1e12 (values from xlfuncs)")
            for a in range(n):
                for b in range(n):
                    book.number(ws, top + a, vb.column + b, Vv[a, b], fmt="0.000000E+00",
                                computed=True)
            book.note(ws.cell(row=top, column=vb.column),
                      f"VALUES, not formulas: V_A,{fac} = G_A|X V_{fac} G_A|X^T computed at build "
                      f"time by {method} (cmmwb {__version__}); V_X "
                      f"({3 * f.m} x {3 * f.m}) is too large for native formulas. In units of 1e-12 "
                      f"(mm^2 -> nm^2, rad^2 -> (µrad)^2), scaled back on the left. Live: the same "
                      f"cells on sheet {LIVE} (add-in function cmm_feature_va)")
            grey[fac] = vb
            book.array(L, f"={vb.ref}*{1 / VALUE_SCALE:.0E}", fmt=SMALL,
                       note=f"V_A,{fac}: the grey values on the right (computed by xlfuncs, "
                            "not formulas) x 1e-12")
        book.array(Gl, f"=MMULT(MMULT({T.ref},{L.ref}),TRANSPOSE({T.ref}))", fmt=SMALL,
                   note="T V_A T^T: covariance of the reported parameters")
        out_local[fac], out_glob[fac] = L, Gl
    book.print_setup(ws, blocks=blocks)
    return {"local": out_local, "global": out_glob, "T": T, "grey": grey}


#: display scale of an uncertainty: mm -> µm, rad -> µrad, a unit-vector component -> 1e-6
_U_DISPLAY = {"mm": (1e3, "µm"), "rad": (1e6, "µrad"), "1": (1e6, "1e-6")}

#: columns of the 'Budget' tables: u and u per factor start in column U_COLUMN, in u_unit
U_COLUMN = 5


def u_display(name: str) -> tuple[float, str]:
    """The display scale and unit of the uncertainty of parameter ``name`` on 'Budget'."""
    return _U_DISPLAY[unit_of(name)]


def _budget_table(book: Book, ws, top: int, names, values, blocks: dict) -> list[tuple[str, int]]:
    """One budget table from row ``top`` (header): parameter, value, unit, u_unit, u and u per
    factor, the uncertainties in µm / µrad (1e-6 for a unit-vector component) from the diagonal
    of the V_A blocks ``blocks`` (which are in the parameters' units squared)."""
    cols = ["parameter", with_units("value", [unit_of(n) for n in names]), "unit", "u_unit",
            *[with_units(u, [u_display(n)[1] for n in names]) for u in
              ("u", *[f"u_{fac}" for fac in pc.FACTORS])]]
    notes = [None, "fitted value, in the unit of column 'unit'", None,
             "unit of u and u_R ... u_P in this row: µm for a length, µrad for an angle, 1e-6 for a "
             "unit-vector component",
             "u = sqrt(diag V_A), in u_unit; u^2 = sum of u_f^2 (Forbes 2025 section 5.6)"] + \
            [f"u_{fac}: sqrt of the diagonal of V_A,{fac}, in u_unit" for fac in pc.FACTORS]
    book.header(ws, top, 1, cols, notes)
    rows = []
    for p, name in enumerate(names):
        r = top + 1 + p
        scale, unit = u_display(name)
        book.text(ws, r, 1, name)
        if isinstance(values[p], float):
            ws.cell(row=r, column=2).value = values[p]
            ws.cell(row=r, column=2).number_format = FMT_VALUE
        else:
            book.formula(ws, r, 2, f"={values[p]}", fmt=FMT_VALUE)
        book.text(ws, r, 3, unit_of(name))
        book.text(ws, r, 4, unit)
        for q, fac in enumerate(("total", *pc.FACTORS)):
            book.formula(ws, r, U_COLUMN + q, f"=SQRT(MAX(0,{blocks[fac].cell(p, p)}))*{scale:g}", fmt="0.0000")
        rows.append((name, r))
    return rows


#: fitted values as a person reads them: 1 nm for lengths, 1e-6 rad / 1e-6 for angles and
#: unit-vector components (the cells keep full precision)
FMT_VALUE = "0.000000"
#: how the units of one table's rows are written in its header: one unit as a suffix (u_um),
#: several as "u (µm, 1e-6)", the row's unit being in column 'unit' / 'u_unit'
_SUFFIX = {"mm": "mm", "µm": "um", "rad": "rad", "µrad": "urad"}


def with_units(label: str, units) -> str:
    """``label`` with the units of the rows of its column: ``u_um`` when all rows share one unit
    that has a key suffix, otherwise ``u (µm, 1e-6)`` (a unit-vector component's unit is 1)."""
    units = list(dict.fromkeys(units))
    if len(units) == 1 and units[0] in _SUFFIX:
        return f"{label}_{_SUFFIX[units[0]]}"
    return f"{label} ({', '.join(units)})"


def write_budget(book: Book, f, va: dict, fitref: dict) -> list[tuple[str, int]]:
    ws = book.sheet("Budget")
    rows = _budget_table(book, ws, 1, f.names, _value_refs(f), va["global"])
    r0 = 2 + len(f.names) + 2
    book.text(ws, r0, 1, "Paper parameters (Forbes 2022, element in standard position in the "
                         "solution frame on 'Fit'); values are offsets from the fit, 0 at the solution",
              font=None)
    values = []
    for p, name in enumerate(f.local_names):
        if name == "r0_mm" and "fit_r0" in fitref and f.kind not in ("sphere", "circle"):
            values.append("fit_r0")
        elif name == "phi_rad":
            values.append("fit_phi")
        elif f.kind in ("sphere", "circle"):
            values.append(_value_refs(f)[p])
        else:
            values.append(0.0)
    paper = _budget_table(book, ws, r0 + 1, f.local_names, values, va["local"])
    _factor_chart(book, ws, paper[-1][1] + 2, rows)
    ws.column_dimensions["A"].width = 14
    ws.freeze_panes = "B2"
    return rows


def _factor_chart(book: Book, ws, anchor: int, rows: list[tuple[str, int]]) -> None:
    """A chart of u per factor of the length parameters in µm (Forbes 2025 section 5.6), on its
    own printed page."""
    from openpyxl.chart import Reference

    length_rows = [r for name, r in rows if unit_of(name) == "mm"]
    if not length_rows:
        return
    first, last = U_COLUMN + 1, U_COLUMN + len(pc.FACTORS)
    book.print_setup(ws, row_breaks=[anchor - 1])   # the chart on its own printed page
    # the chart's categories in words, in the row above it (the headers carry units)
    book.text(ws, anchor, 1, "influence factor (chart axis)")
    for q, fac in enumerate(pc.FACTORS):
        book.text(ws, anchor, first + q, FACTOR_WORDS[fac])
    book.bars(ws, f"A{anchor + 1}", "u per influence factor of the length parameters (µm), "
              "Forbes 2025 section 5.6", "u / µm",
              Reference(ws, min_col=first, max_col=last, min_row=anchor),
              [(ws.cell(row=r, column=1).value, Reference(ws, min_col=first, max_col=last,
                                                          min_row=r, max_row=r))
               for r in length_rows], horizontal=False, width=18, height=8, page=book)


#: the influence factors of Forbes 2025 (Table 3) as the chart names them: "ET location errors"
FACTOR_WORDS = {fac: f"{fac} {title.split(',')[0]}" for fac, title in FACTOR_TITLES.items()}


def unit_of(name: str) -> str:
    return "mm" if name.endswith("_mm") else "rad" if name.endswith("_rad") else "1"


def _value_refs(f) -> list[str]:
    o = [cell(3, 2 + a, "Fit") for a in range(3)]
    if f.kind == "sphere":
        return [*o, "fit_r0"]
    if f.kind == "circle":
        from cmmwb.xlfuncs.features import CIRCLE_PLANES

        cols, _ = CIRCLE_PLANES[f.circle_plane]
        return [o[cols[0]], o[cols[1]], "fit_r0"]
    v = [cell(5 + a, 4, "Fit") for a in range(3)]
    out = [*o, *v]
    if f.kind in ("cylinder", "circle_space", "cone"):
        out.append("fit_r0")
    if f.kind == "cone":
        out.append("fit_phi")
    return out
