"""One budget block of the ``budget`` workbook: the budget of one variant of one distance in the
layout of Wojtyła/Płowucha 2023 Tables 1-8 (input, x_i in mm, dl/dx_i, u_i in µm, contribution,
then l, u_c, U), its intermediate quantities and degrees of freedom (GUM G.4), as plain
single-cell formulas of the named inputs: u_i = b (A_um + |x_i|/B_mm) (eq. (5)),
u_c = SQRT(SUMSQ(...)) (eq. (6)), U = k u_c."""

from __future__ import annotations

from dataclasses import dataclass, field

from openpyxl.styles import Alignment

from cmmwb.xlfuncs import budget as bd
from cmmwb.xlfuncs import dof
from cmmwb.xlfuncs.model.workpiece import REFERENCE_C

from ..workbook.book import Book
from ..workbook.styles import FMT_SCI, HEADER_FONT
from ..workbook.xlref import block, cell
from .task import TYPE_A_INPUT

# columns of a budget block (paper layout) and of its intermediate quantities
C_INPUT, C_X, C_S, C_U, C_C = 1, 2, 3, 4, 5
C_QTY, C_VX, C_VY, C_VZ, C_MEAN = 7, 8, 9, 10, 11
# degrees of freedom, after every existing column (GUM G.4): distribution and ν of each input,
# and to their right, below, ν_eff of u_c (and the type A combination)
C_DIST, C_NU = 12, 13

FMT_X = "0.00##"          # mm, as entered
FMT_S = "0.0000"          # sensitivities, 4 decimals
FMT_Q = FMT_SCI           # intermediate quantities (cross products span decades)
FMT_U = "0.0000"          # µm

BUDGET_HEADER = ["input", "x_i_mm", "dl_dx_i_mm/mm", "u_i_um", "contribution_um"]
BUDGET_NOTES = [
    "Input quantity x_i: a coordinate difference of two essential points, e.g. x_CS4 = x(S4) - x(C) "
    "(Wojtyła/Płowucha 2023, section 2).",
    "Value of the input quantity in mm, a formula of the named point coordinates on 'Inputs'.",
    "Sensitivity dl/dx_i: closed-form derivative of the model, written with the intermediate "
    "quantities to the right (columns G-K).",
    "u(x_i) = b * E_L,MPE(|x_i|) = b * (A_um + |x_i|/B_mm), eq. (5) applied to each coordinate "
    "difference.",
    "Contribution dl/dx_i * u_i (µm); u_c = sqrt(sum of squares), eq. (6).",
]
DOF_HEADER = ["distribution", "nu"]
DOF_NOTES = [
    "Distribution of the input: u = b * E_L,MPE with b = 1/sqrt(3) (0.577) is the standard deviation of a "
    "rectangular distribution, b = 1/sqrt(6) (0.408) of a triangular one (GUM 4.3.7, 4.3.9); any other b is "
    "read as the standard deviation of a normal distribution (docs/errata.md). A live formula of b.",
    "Degrees of freedom nu_i: an input from an MPE statement is type B, known without uncertainty of its "
    "own: nu = infinity, shown as the text \"∞\" (GUM G.4.2, G.4.3); a type A repeatability has nu = n - 1 "
    "(GUM G.3.3). Type a number to give a type B input finite nu (GUM eq. (G.3)).",
]
NU_INF = "∞"
NU_EFF_NOTE = ("nu_eff by Welch-Satterthwaite, GUM G.4.1 eq. (G.2b): u^4 / sum((c_i u_i)^4 / nu_i) over "
               "the rows whose nu is a number; \"∞\" when every input has nu = ∞ (all type B)")

KIND_TEXT = {
    "point_point": "l = |p|, eq. (1)",
    "point_line": "l = |p x a|/|a|, eq. (2)",
    "plane": "l = |p . n|/|n|, n = a x c, eqs. (3), (7), (10)-(18)",
    "line_line": "l = |p . n|/|n|, n = a x c, eq. (4)",
    "secondary": "l = |p . v|/|v|, v = d x u, u = a x c, eqs. (8), (27)-(32)",
    "tertiary": "l = |p . w|/|w|, w = u x v, v = d x u, u = a x c, eqs. (9), (19)-(21), (33)-(35)",
}
SENS_TEXT = {
    "point_point": "dl/dp = p/|p|",
    "point_line": "dl/dp = (a x m)/(|m||a|), dl/da = (m x p)/(|m||a|) - |m| a/|a|^3, m = p x a",
    "plane": "dl/dp = s n/|n|, dl/da = c x g, dl/dc = g x a, g = dl/dn = s (p - t n/|n|)/|n|",
    "line_line": "dl/dp = s n/|n|, dl/da = c x g, dl/dc = g x a, g = dl/dn = s (p - t n/|n|)/|n|",
    "secondary": "dl/dp = s v/|v|; g = dl/dv; dl/dd = u x g; g_u = g x d; dl/da = c x g_u, "
                 "dl/dc = g_u x a",
    "tertiary": "dl/dp = s w/|w|; g = dl/dw; g_v = g x u; dl/dd = u x g_v; g_u = v x g + g_v x d; "
                "dl/da = c x g_u, dl/dc = g_u x a",
}


@dataclass
class BudgetCells:
    """Where one variant's budget is (coordinates on ``sheet``)."""

    sheet: str
    label: str
    rows: list[dict]             # {"input", "value", "sensitivity", "u", "contribution", "distribution", "nu"}
    value: str
    u: str
    U: str
    nu_eff: str = ""             #: ν_eff of u_c (or of u_with_A when type_a)
    type_a: dict | None = None   #: {"u", "nu", "u_with", "k", "U_with"} cells of the type A row
    thermal: list[dict] = field(default_factory=list)   #: the rows of the factor W, as ``rows``


@dataclass
class CharCells:
    """Where a characteristic's results are: ``value``, ``u``, ``U`` (and, for a position, the
    combination ``rows`` and the two distances)."""

    sheet: str
    value: str
    u: str
    U: str
    rows: list[dict] = field(default_factory=list)
    nu_eff: str = ""
    type_a: dict | None = None
    chosen: BudgetCells | None = None
    variants: dict[str, BudgetCells] = field(default_factory=dict)
    distances: list["CharCells"] = field(default_factory=list)
    results_row: int = 0


# -- formula text helpers (no leading "=") --------------------------------------------------------

def _cross(a: list[str], c: list[str]) -> list[str]:
    return [f"{a[1]}*{c[2]}-{a[2]}*{c[1]}", f"{a[2]}*{c[0]}-{a[0]}*{c[2]}",
            f"{a[0]}*{c[1]}-{a[1]}*{c[0]}"]


def _dot(a: list[str], c: list[str]) -> str:
    return f"{a[0]}*{c[0]}+{a[1]}*{c[1]}+{a[2]}*{c[2]}"


def coord(ref: str) -> str:
    return ref.replace("$", "")


# -- one variant's budget ---------------------------------------------------------------------------

class _BlockWriter:
    def __init__(self, book: Book, ws, r0: int):
        self.book, self.ws, self.r0 = book, ws, r0
        self.qrow = r0 + 2          # next row of the intermediate quantities

    def vec(self, label: str, comps: list[str], meaning: str) -> list[str]:
        r = self.qrow
        self.book.text(self.ws, r, C_QTY, label)
        for k, f in enumerate(comps):
            self.book.formula(self.ws, r, C_VX + k, f"={f}", fmt=FMT_Q)
        _meaning(self.book, self.ws, r, meaning)
        self.qrow += 1
        return [cell(r, C_VX + k) for k in range(3)]

    def scalar(self, label: str, formula: str, meaning: str) -> str:
        r = self.qrow
        self.book.text(self.ws, r, C_QTY, label)
        self.book.formula(self.ws, r, C_VX, f"={formula}", fmt=FMT_Q)
        _meaning(self.book, self.ws, r, meaning)
        self.qrow += 1
        return cell(r, C_VX)

    def norm(self, v: list[str]) -> str:
        return f"SQRT(SUMSQ({v[0]}:{v[2]}))"


def _meaning(book: Book, ws, r: int, meaning: str) -> None:
    """The 'meaning' of an intermediate: indented away from the numbers on its left, wrapped
    within its column (it ran into the z column's numbers)."""
    c = book.text(ws, r, C_MEAN, meaning)
    c.alignment = Alignment(horizontal="left", wrap_text=True, vertical="top", indent=1)


def _point_refs(vec: bd.Vec) -> list[str]:
    return [f"{vec.head}_{ax}_mm-{vec.tail}_{ax}_mm" for ax in bd.AXES]


def _distribution_formula() -> str:
    """The distribution that b implies, live (:func:`xlfuncs.dof.distribution_of_b`)."""
    t = f"{dof.B_TOLERANCE:g}"
    return (f'=IF(ABS(b-1/SQRT(3))<={t},"rectangular",IF(ABS(b-1/SQRT(6))<={t},"triangular",'
            f'"{dof.B_OTHER}"))')


def nu_eff_formula(u: str, rows: list[int], c_contribution: int, c_nu: int) -> str:
    """ν_eff = u^4 / Σ c_i^4/ν_i (GUM eq. (G.2b)) over the rows whose ν cell is a number; the
    text "∞" when none is (all inputs type B)."""
    terms = "+".join(f"IF(ISNUMBER({cell(r, c_nu)}),{cell(r, c_contribution)}^4/{cell(r, c_nu)},0)"
                     for r in rows)
    return f'=IF(({terms})=0,"{NU_INF}",{u}^4/({terms}))'


def type_a_cells(book: Book, ws, r: int, c_label: int, c_value: int, u: str, contrib: str,
                  a: dict, nu_rows: list[int], c_contribution: int, c_nu: int) -> tuple[dict, str]:
    """u_with_A = sqrt(u^2 + u_A^2), ν_eff, k and U_with_A as label/value cells from row ``r``
    down (GUM 4.2.3, G.4.1, G.6.4); returns the cells and ν_eff's."""
    labels = ["u_with_A_um", "nu_eff", "k", "U_with_A_um"]
    for j, lab in enumerate(labels):
        book.text(ws, r + j, c_label, lab)
    uw = cell(r, c_value)
    book.formula(ws, r, c_value, f"=SQRT({u}^2+{contrib}^2)", fmt=FMT_U,
                 note="u with the type A repeatability: sqrt(u_c^2 + u_A^2) (GUM 5.1.2); "
                      "what the Decision sheet decides with")
    book.formula(ws, r + 1, c_value, nu_eff_formula(uw, nu_rows, c_contribution, c_nu), fmt="0.00",
                 note=NU_EFF_NOTE)
    if a["k_from_dof"]:
        book.formula(ws, r + 2, c_value, f"=_xlfn.T.INV.2T(1-{dof.P_K2},INT({cell(r + 1, c_value)}))",
                     fmt="0.000", note="k = t_95.45(nu) for nu = floor(nu_eff), [decision] k_from_dof "
                                       "(GUM G.6.4)")
    else:
        book.formula(ws, r + 2, c_value, "=k", fmt="0.000",
                     note="the task's k; [decision] k_from_dof = true takes k from the t-distribution")
    book.formula(ws, r + 3, c_value, f"={cell(r + 2, c_value)}*{uw}", fmt=FMT_U, note="U = k u_with_A")
    got = {"u_with": uw, "k": cell(r + 2, c_value), "U_with": cell(r + 3, c_value)}
    return {k: coord(v) for k, v in got.items()}, coord(cell(r + 1, c_value))


def write_variant(book: Book, ws, r0: int, title: str, vb: bd.VariantBudget, *,
                  notes: bool, type_a: dict | None = None) -> tuple[BudgetCells, int]:
    """Write one variant's budget with its top-left at row ``r0``; return its cells and the
    first free row below it.  ``type_a`` (:func:`generator.budget.job.type_a`): a type A
    repeatability given in ``[[decision.tolerances]]``, written as a row below the inputs."""
    spec = vb.spec
    w = _BlockWriter(book, ws, r0)
    book.text(ws, r0, C_INPUT, title, font=HEADER_FONT)
    book.header(ws, r0 + 1, C_INPUT, BUDGET_HEADER,
                [*BUDGET_NOTES[:2], f"{BUDGET_NOTES[2]} Here: {SENS_TEXT[spec.kind]}.",
                 *BUDGET_NOTES[3:]] if notes else None)
    book.header(ws, r0 + 1, C_QTY, ["intermediate", "x", "y", "z", "meaning"],
                [None, "x component (unit: mm for coordinate vectors, mm² for cross products, mm/mm "
                 "for gradients)", "y component", "z component", None] if notes else None)
    book.header(ws, r0 + 1, C_DIST, DOF_HEADER, DOF_NOTES if notes else None)

    # input quantities: x_i = coordinate differences of named points
    vecs: dict[str, list[str]] = {}
    rows = []
    r = r0 + 2
    for v in spec.vectors:
        refs = []
        for k, (name, f) in enumerate(zip(v.inputs, _point_refs(v))):
            book.text(ws, r, C_INPUT, name)
            book.formula(ws, r, C_X, f"={f}", fmt=FMT_X)
            book.formula(ws, r, C_U, f"=b*(A_um+ABS({cell(r, C_X)})/B_mm)", fmt=FMT_U)
            book.formula(ws, r, C_C, f"={cell(r, C_S)}*{cell(r, C_U)}", fmt=FMT_U)
            book.formula(ws, r, C_DIST, _distribution_formula(), fmt=None)
            book.text(ws, r, C_NU, NU_INF).alignment = Alignment(horizontal="right")
            refs.append(cell(r, C_X))
            rows.append({"input": name, "value": coord(cell(r, C_X)),
                         "sensitivity": coord(cell(r, C_S)), "u": coord(cell(r, C_U)),
                         "contribution": coord(cell(r, C_C)), "distribution": coord(cell(r, C_DIST)),
                         "nu": coord(cell(r, C_NU))})
            r += 1
        vecs[v.role] = refs
    lab = {v.role: v.label for v in spec.vectors}
    p = vecs.get("p")

    # intermediate quantities and the sensitivities, per formula skeleton
    sens: dict[str, list[str]] = {}
    kind = spec.kind
    if kind == "point_point":
        P = w.scalar("|p|", w.norm(p), f"|{lab['p']}|, eq. (1)")
        value = P
        sens["p"] = [f"{x}/{P}" for x in p]
    elif kind == "point_line":
        a = vecs["a"]
        m = w.vec("m = p x a", _cross(p, a), f"{lab['p']} x {lab['a']}")
        M = w.scalar("|m|", w.norm(m), "length of m")
        A = w.scalar("|a|", w.norm(a), f"|{lab['a']}|")
        q = w.vec("a x m", _cross(a, m), "for dl/dp")
        qq = w.vec("m x p", _cross(m, p), "for dl/da")
        value = f"{M}/{A}"
        sens["p"] = [f"{x}/({M}*{A})" for x in q]
        sens["a"] = [f"{x}/({M}*{A})-{M}*{y}/{A}^3" for x, y in zip(qq, a)]
    else:
        a, c = vecs["a"], vecs["c"]
        if kind in ("plane", "line_line"):
            n = w.vec("n = a x c", _cross(a, c), f"{lab['a']} x {lab['c']}"
                      + (", eq. (7)" if kind == "plane" else ", eq. (4)"))
        else:
            d = vecs["d"]
            u = w.vec("u = a x c", _cross(a, c), f"{lab['a']} x {lab['c']}, eq. (7)")
            v = w.vec("v = d x u", _cross(d, u), f"{lab['d']} x u, eq. (8)")
            if kind == "secondary":
                n = v
            else:
                n = w.vec("w = u x v", _cross(u, v), "u x (DE x u), eq. (9)")
        N = w.scalar("|n|", w.norm(n), "length of the normal")
        t = w.scalar("t = p.n/|n|", f"({_dot(p, n)})/{N}", f"signed distance of {lab['p']}")
        s = w.scalar("s", f"IF({t}<0,-1,1)", "sign of t (+1 at t = 0: one-sided derivative)")
        g = w.vec("g = dl/dn", [f"{s}*({pp}-{t}*{nn}/{N})/{N}" for pp, nn in zip(p, n)],
                  "s (p - t n/|n|)/|n|")
        value = f"ABS({t})"
        sens["p"] = [f"{s}*{nn}/{N}" for nn in n]
        if kind in ("plane", "line_line"):
            gu = g
        elif kind == "secondary":
            gu = w.vec("g_u = dl/du", _cross(g, vecs["d"]), "g x d")
            sens["d"] = _cross(u, g)
        else:
            gv = w.vec("g_v = dl/dv", _cross(g, u), "g x u")
            gu = w.vec("g_u = dl/du", [f"({x})+({y})" for x, y in
                                       zip(_cross(v, g), _cross(gv, vecs["d"]))],
                       "v x g + g_v x d")
            sens["d"] = _cross(u, gv)
        sens["a"] = _cross(c, gu)
        sens["c"] = _cross(gu, a)

    r = r0 + 2
    for v in spec.vectors:
        for f in sens[v.role]:
            book.formula(ws, r, C_S, f"={f}", fmt=FMT_S)
            r += 1
    # the factor W (docs/workpiece.md): rows of alpha, T, dT and the uncorrected expansion, in u_c
    thermal = []
    if vb.thermal:
        value_row = r + len(vb.thermal) + (1 if type_a is not None else 0)
        thermal = _thermal_rows(book, ws, r, cell(value_row, C_C), notes)
        r += len(thermal)
    last_input = r - 1
    nu_rows = list(range(r0 + 2, r))
    a_cells = None
    value_cell = (r, C_C)
    book.text(ws, r, C_U, "l_mm")
    book.formula(ws, r, C_C, f"={value}", fmt="0.0000",
                 note=f"{KIND_TEXT[kind]}: {spec.label} ({spec.equation})" if notes else None)
    book.text(ws, r + 1, C_U, "u_c_um")
    book.formula(ws, r + 1, C_C, f"=SQRT(SUMSQ({block(r0 + 2, C_C, last_input - r0 - 1, 1)}))",
                 fmt=FMT_U, note=("u_c = sqrt(sum((dl/dx_i u_i)^2)), eq. (6)"
                                  + (", with the rows of the part's temperature (W)" if thermal else ""))
                 if notes else None)
    book.text(ws, r + 2, C_U, "U_um")
    book.formula(ws, r + 2, C_C, f"=k*{cell(r + 1, C_C)}", fmt=FMT_U,
                 note="U = k u_c" if notes else None)
    book.text(ws, r + 1, C_DIST, "nu_eff")
    book.formula(ws, r + 1, C_NU, nu_eff_formula(cell(r + 1, C_C), nu_rows, C_C, C_NU), fmt="0.00",
                 note=NU_EFF_NOTE).alignment = Alignment(horizontal="right")
    nu_eff = coord(cell(r + 1, C_NU))
    bottom = max(r + 3, w.qrow)
    if type_a is not None:
        # the measured result below the budget, which stays whole (every row above is in u_c):
        # u_c with the repeatability of the measured value, what the Decision sheet and the
        # Summary state (the Results sheet reports the budget's u_c and U)
        book.text(ws, r + 3, C_INPUT, "The measured result (Decision and Summary): u_c of the budget above and "
                  "the repeatability of the measured value", font=HEADER_FONT)
        a_cells = _type_a_row(book, ws, r + 4, type_a)
        got, nu_eff = type_a_cells(book, ws, r + 5, C_U, C_C, cell(r + 1, C_C), a_cells["contribution"],
                                    type_a, nu_rows + [r + 4], C_C, C_NU)
        a_cells.update(got)
        bottom = max(r + 9, w.qrow)
    cells = BudgetCells(ws.title, spec.label, rows, coord(cell(*value_cell)),
                        coord(cell(r + 1, C_C)), coord(cell(r + 2, C_C)), nu_eff,
                        {k: coord(v) for k, v in a_cells.items()} if a_cells else None, thermal)
    return cells, bottom + 1


#: the W rows of a budget (docs/workpiece.md): label, value, sensitivity (l the characteristic's cell),
#: u, distribution; every u times workpiece_enabled
_W = "workpiece_"
THERMAL_ROWS = (
    ("alpha_ppm_per_K (W)", f"={_W}alpha_ppm_per_K", f"=-{{l}}*({_W}T_degC-{REFERENCE_C:g})*0.001",
     f"={_W}u_alpha_ppm_per_K*{_W}enabled", "normal",
     "alpha of the part (1e-6/K); dl/dalpha = -l (T - 20) x 0.001 µm per 1e-6/K; u = u(alpha)"),
    ("T_degC (W)", f"={_W}T_degC", f"=-{{l}}*{_W}alpha_ppm_per_K*0.001", f"={_W}u_T_K*{_W}enabled", "normal",
     "the part's temperature (°C); dl/dT = -l alpha x 0.001 µm per K; u = u(T)"),
    ("dT_K across the part (W)", f"={_W}dT_K", f"=-{{l}}*{_W}alpha_ppm_per_K*0.001",
     f"={_W}dT_K/SQRT(12)*{_W}enabled", "rectangular",
     "temperature difference across the part (K): a rectangular spread of T, u = dT/sqrt(12)"),
    ("b_uncorrected_ppm (W)", f"={_W}bias_ppm", "={l}*0.001", f"=ABS({_W}bias_ppm)*{_W}enabled",
     "uncorrected (RSS)",
     "the expansion the CMM leaves uncorrected, b = (alpha - alpha_c)(T - 20) (1e-6): a known systematic "
     "error carried in quadrature (RSSu, docs/workpiece.md); 0 when the CMM corrects with the part's alpha"),
)


def _thermal_rows(book: Book, ws, r: int, l_cell: str, notes: bool) -> list[dict]:
    """The rows of the factor W from row ``r`` (Wojtyła/Płowucha layout: input, value, dl/dx_i, u_i,
    contribution; the units are in the input's label), l the characteristic (``l_cell``)."""
    out = []
    for label, value, sens, u, dist, meaning in THERMAL_ROWS:
        c = book.text(ws, r, C_INPUT, label)
        if notes:
            book.note(c, meaning)
        book.formula(ws, r, C_X, value, fmt="0.00##")
        book.formula(ws, r, C_S, sens.format(l=l_cell), fmt=FMT_S)
        book.formula(ws, r, C_U, u, fmt=FMT_U)
        book.formula(ws, r, C_C, f"={cell(r, C_S)}*{cell(r, C_U)}", fmt=FMT_U)
        book.text(ws, r, C_DIST, dist)
        book.text(ws, r, C_NU, NU_INF).alignment = Alignment(horizontal="right")
        out.append({"input": label, "value": coord(cell(r, C_X)), "sensitivity": coord(cell(r, C_S)),
                    "u": coord(cell(r, C_U)), "contribution": coord(cell(r, C_C)),
                    "distribution": coord(cell(r, C_DIST)), "nu": coord(cell(r, C_NU))})
        r += 1
    return out


def _type_a_row(book: Book, ws, r: int, a: dict) -> dict:
    """The type A repeatability of ``[[decision.tolerances]]`` #n as a budget row: u_A = s/√n
    (the Decision sheet's named inputs tol<n>_s_um, tol<n>_n_repeats), sensitivity 1, normal,
    ν = n - 1 (GUM 4.2.3, G.3.3), below the budget: not in u_c (eq. (6), the MPE inputs, as the
    Results sheet reports it); combined in u_with_A, the U of the measured result."""
    n = a["tolerance"]
    book.text(ws, r, C_INPUT, TYPE_A_INPUT)
    book.text(ws, r, C_X, "—").alignment = Alignment(horizontal="right")
    book.formula(ws, r, C_S, "=1", fmt="0")
    book.formula(ws, r, C_U, f"=tol{n}_s_um/SQRT(tol{n}_n_repeats)", fmt=FMT_U,
                 note=f"u_A = s/sqrt(n): the repeatability of [[decision.tolerances]] #{n} (its s_um, "
                      "n_repeats are input cells on the Decision sheet), GUM 4.2.3. Not part of u_c "
                      "(eq. (6), the budget above); combined in u_with_A_um, the U of the measured result")
    book.formula(ws, r, C_C, f"={cell(r, C_S)}*{cell(r, C_U)}", fmt=FMT_U)
    book.text(ws, r, C_DIST, "normal")
    book.formula(ws, r, C_NU, f"=tol{n}_n_repeats-1", fmt="0", note="nu = n - 1 (GUM G.3.3)")
    return {"u": cell(r, C_U), "contribution": cell(r, C_C), "nu": cell(r, C_NU)}
