"""The sensitivity columns of the diagnosis workbook as formula text, one entry per family of
effects (``FORMULAS``, keyed like ``xlfuncs.locator.effects.FAMILIES``).

Every function returns the formula of one cell of a record's row (``=...``; a point record's
coordinate that an effect does not move is the number 0.0): the same expression as the core's
column of that family (``effects.FAMILIES[family].length`` / ``.point``), written over the record
cells (probe offsets, normals, temperatures, times) so that the refit stays live.
``tests/diagnosis/test_diagnose_effect_formulas.py`` recomputes every effect's columns with ``formulas`` and
compares them with the core's to relative 1e-9.  Only the functions of docs/engines.md (SQRT, SIN,
COS, PI, IF, EXACT) and plain arithmetic are used.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from cmmwb.xlfuncs.locator import effects as fx

from ..workbook.xlref import cell


class Row:
    """Cell addresses of one record (or point) row by column key."""

    def __init__(self, sheet: str, row: int, cols: dict[str, int]):
        self.sheet, self.row, self.cols = sheet, row, cols

    def __getitem__(self, key: str) -> str:
        return cell(self.row, self.cols[key], self.sheet)

    def has(self, key: str) -> bool:
        return key in self.cols


# -- building blocks (no leading '=') ------------------------------------------------------------

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


def _na_dot(R: Row, v: tuple[str, str, str]) -> str:
    terms = [f"{R['na' + ax]}*{v[a]}" for a, ax in enumerate("xyz") if v[a] != "0"]
    return "(" + "+".join(terms) + ")" if terms else "0"


def _rot_vec(rot: str, p: tuple[str, str, str]) -> tuple[str, str, str]:
    """e_R x p as formula strings (A: (0, -pz, py), B: (pz, 0, -px), C: (-py, px, 0))."""
    px, py, pz = p
    return {"A": ("0", f"(-{pz})", py), "B": (pz, "0", f"(-{px})"), "C": (f"(-{py})", px, "0")}[rot]


def _du(R: Row) -> dict[str, str]:
    """u2 - u1 per axis of a length record's row."""
    return {ax: f"({R['u' + ax + '2_mm']}-{R['u' + ax + '1_mm']})" for ax in "xyz"}


def _ndu(R: Row) -> str:
    """n_a . (u2 - u1)."""
    du = _du(R)
    return "(" + "+".join(f"{R['na' + ax]}*{du[ax]}" for ax in "xyz") + ")"


def _normals_dot(R: Row) -> tuple[str, str]:
    """n_a . n2 and n_a . n1."""
    return (_na_dot(R, tuple(R[f"n2{ax}"] for ax in "xyz")), _na_dot(R, tuple(R[f"n1{ax}"] for ax in "xyz")))


# -- length records: (name, parameter label, row, probe cells, travel cells) -> "=..." -------------

def _scale_length(name, par, R, probe_cells, travel):
    return f"=0.001*{_ndu(R)}"


def _scale_axis_length(name, par, R, probe_cells, travel):
    ax = name[-1]
    return f"=0.001*{R['na' + ax]}*{_du(R)[ax]}"


def _squareness_length(name, par, R, probe_cells, travel):
    return f"=0.001*{R['na' + name[-2]]}*{_du(R)[name[-1]]}"


def _thermal_expansion_length(name, par, R, probe_cells, travel):
    return f"=0.001*({R['temperature_C']}-20)*{R['reference_mm']}"


def _probe_radius_length(name, par, R, probe_cells, travel):
    n2, n1 = _normals_dot(R)
    return f"={n2}-{n1}"


def _probe_qualification_length(name, par, R, probe_cells, travel):
    pid, comp = par.rsplit(".d", 1)
    k = probe_cells[pid]
    return f"={R['na' + comp]}*(EXACT({R['probe2']},{k})*1-EXACT({R['probe1']},{k})*1)"


def _angular_length(name, par, R, probe_cells, travel):
    rot, car = name[1], name[2].lower()
    v1 = _rot_vec(rot, tuple(R[f"p1{ax}"] for ax in "xyz"))
    v2 = _rot_vec(rot, tuple(R[f"p2{ax}"] for ax in "xyz"))
    return f"=0.000001*({R['u' + car + '2_mm']}*{_na_dot(R, v2)}-{R['u' + car + '1_mm']}*{_na_dot(R, v1)})"


def _scale_drift_length(name, par, R, probe_cells, travel):
    return f"=0.001*({R['time_s']}/3600)*{_ndu(R)}"


def _straightness_length(name, par, R, probe_cells, travel):
    k, car, dev = int(par[1]), name[2], name[1].lower()
    p2 = _legendre_formula(k, R[f"u{car.lower()}2_mm"], travel[car])
    p1 = _legendre_formula(k, R[f"u{car.lower()}1_mm"], travel[car])
    return f"={R['na' + dev]}*({p2}-{p1})"


def _reversal_length(name, par, R, probe_cells, travel):
    ax = name[-1]
    return f"={R['na' + ax]}*({_approach_formula(R['n2' + ax])}-{_approach_formula(R['n1' + ax])})"


def _probe_lobing_length(name, par, R, probe_cells, travel):
    pid, h = par.rsplit(".", 1)
    k = probe_cells[pid]
    n2, n1 = _normals_dot(R)
    return (f"={n2}*{_harmonic_formula(h, R['n2x'], R['n2y'])}*EXACT({R['probe2']},{k})*1"
            f"-{n1}*{_harmonic_formula(h, R['n1x'], R['n1y'])}*EXACT({R['probe1']},{k})*1")


def _periodic_length(name, par, R, probe_cells, travel):
    ax = name[-1]
    f2 = _periodic_formula(par, R[f"u{ax}2_mm"], ax, travel)
    f1 = _periodic_formula(par, R[f"u{ax}1_mm"], ax, travel)
    return f"={R['na' + ax]}*({f2}-{f1})"


def _thermal_gradient_length(name, par, R, probe_cells, travel):
    ax = name[-1]
    lo, hi = travel["pos_" + ax]
    mid = f"(({R[ax + '1']}+{R[ax + '2']})/2-({lo}+{hi})/2)"
    return f"=0.000001*({R['temperature_C']}-20)*{R['reference_mm']}*{mid}"


# -- point records: (name, parameter label, coordinate a, row, centroid cells, probe cells, travel)
#    -> "=..." or 0.0 ----------------------------------------------------------------------------

def _rel(P: Row, c: dict, k: str) -> str:
    """The ram position about the centroid along k."""
    return f"({P['u' + k + '_mm']}-{c[k]})"


def _scale_point(name, par, a, P, c, probe_cells, travel):
    return f"=0.001*{_rel(P, c, 'xyz'[a])}"


def _scale_axis_point(name, par, a, P, c, probe_cells, travel):
    ax = "xyz"[a]
    return f"=0.001*{_rel(P, c, ax)}" if name[-1] == ax else 0.0


def _squareness_point(name, par, a, P, c, probe_cells, travel):
    return f"=0.001*{_rel(P, c, name[-1])}" if name[-2] == "xyz"[a] else 0.0


def _thermal_expansion_point(name, par, a, P, c, probe_cells, travel):
    ax = "xyz"[a]
    return f"=0.001*({P['temperature_C']}-20)*({P['y' + ax + '_mm']}-{c[ax]})"


def _probe_radius_point(name, par, a, P, c, probe_cells, travel):
    return f"={P['n' + 'xyz'[a]]}"


def _probe_qualification_point(name, par, a, P, c, probe_cells, travel):
    pid, comp = par.rsplit(".d", 1)
    return f"=EXACT({P['probe']},{probe_cells[pid]})*1" if comp == "xyz"[a] else 0.0


def _angular_point(name, par, a, P, c, probe_cells, travel):
    rot, car = name[1], name[2].lower()
    v = _rot_vec(rot, tuple(P[f"p{k}"] for k in "xyz"))[a]
    return 0.0 if v == "0" else f"=0.000001*{P['u' + car + '_mm']}*{v}"


def _scale_drift_point(name, par, a, P, c, probe_cells, travel):
    return f"=0.001*({P['time_s']}/3600)*{_rel(P, c, 'xyz'[a])}"


def _offset_drift_point(name, par, a, P, c, probe_cells, travel):
    return f"={P['time_s']}/3600" if par == f"v{'xyz'[a]}" else 0.0


def _straightness_point(name, par, a, P, c, probe_cells, travel):
    car = name[2]
    return ("=" + _legendre_formula(int(par[1]), P[f"u{car.lower()}_mm"], travel[car])
            if name[1].lower() == "xyz"[a] else 0.0)


def _reversal_point(name, par, a, P, c, probe_cells, travel):
    ax = "xyz"[a]
    return "=" + _approach_formula(P["n" + ax]) if name[-1] == ax else 0.0


def _probe_lobing_point(name, par, a, P, c, probe_cells, travel):
    pid, h = par.rsplit(".", 1)
    return (f"={P['n' + 'xyz'[a]]}*{_harmonic_formula(h, P['nx'], P['ny'])}"
            f"*EXACT({P['probe']},{probe_cells[pid]})*1")


def _periodic_point(name, par, a, P, c, probe_cells, travel):
    ax = "xyz"[a]
    return "=" + _periodic_formula(par, P[f"u{ax}_mm"], ax, travel) if name[-1] == ax else 0.0


def _thermal_gradient_point(name, par, a, P, c, probe_cells, travel):
    ax, g = "xyz"[a], name[-1]
    return (f"=0.000001*({P['temperature_C']}-20)*({P['y' + g + '_mm']}-{c[g]})"
            f"*({P['y' + ax + '_mm']}-{c[ax]})")


@dataclass(frozen=True)
class Formulas:
    """The workbook's formulas of one family of effects: for a length record's row (None: the
    family does not apply to lengths) and for one coordinate of a point record."""

    length: Callable[..., str] | None
    point: Callable[..., str | float]


#: one entry per family of ``xlfuncs.locator.effects.FAMILIES`` (same keys, checked by
#: tests/diagnosis/test_diagnose_effect_formulas.py, which also compares the values cell by cell)
FORMULAS: dict[str, Formulas] = {
    "scale": Formulas(_scale_length, _scale_point),
    "scale_axis": Formulas(_scale_axis_length, _scale_axis_point),
    "squareness": Formulas(_squareness_length, _squareness_point),
    "thermal_expansion": Formulas(_thermal_expansion_length, _thermal_expansion_point),
    "probe_radius": Formulas(_probe_radius_length, _probe_radius_point),
    "probe_qualification": Formulas(_probe_qualification_length, _probe_qualification_point),
    "angular": Formulas(_angular_length, _angular_point),
    "scale_drift": Formulas(_scale_drift_length, _scale_drift_point),
    "offset_drift": Formulas(None, _offset_drift_point),
    "straightness": Formulas(_straightness_length, _straightness_point),
    "reversal": Formulas(_reversal_length, _reversal_point),
    "probe_lobing": Formulas(_probe_lobing_length, _probe_lobing_point),
    "thermal_gradient": Formulas(_thermal_gradient_length, _thermal_gradient_point),
    "periodic": Formulas(_periodic_length, _periodic_point),
}


def _family(name: str) -> Formulas:
    return FORMULAS[fx.BY_NAME[name].family]


def length_formula(name: str, par: str, R: Row, probe_cells: dict[str, str],
                   travel: dict[str, tuple[str, str]] | None = None) -> str:
    """Sensitivity of a length record to one parameter, as a formula of its row (effects.py);
    ``travel``: the lo/hi cells of the straightness carriages (records.travel_cells)."""
    f = _family(name).length if name in fx.BY_NAME else None
    if f is None:
        raise ValueError(f"no length formula for {name}")
    return f(name, par, R, probe_cells, travel)


def point_formula(name: str, par: str, a: int, P: Row, c: dict, probe_cells: dict[str, str],
                  travel: dict[str, tuple[str, str]] | None = None) -> str | float:
    """Sensitivity of coordinate a of a point record to one parameter (effects.py, point rows);
    ``travel``: the lo/hi cells of the straightness carriages (records.travel_cells)."""
    if name not in fx.BY_NAME:
        raise ValueError(f"no point formula for {name}")
    return _family(name).point(name, par, a, P, c, probe_cells, travel)


def alignment_formula(label: str, a: int, P: Row, c: dict) -> str | float:
    """The rigid alignment's column of coordinate a of a point record (effects.alignment_columns):
    a translation t<axis> (1 or 0) or a small rotation w<axis> (µrad), 0.001 omega x (y - c)."""
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
