"""Sensitivity-analysis uncertainty budgets from E_L,MPE (Wojtyła, Płowucha et al. 2023).

Measurement models (Wojtyła/Płowucha 2023, section 2 and section 3) express a characteristic
as a distance ``l`` that is a function of the coordinate differences of a few *essential
points*.  The input quantities ``x_i`` are those coordinate differences (``x_CS4``,
``y_CS4``, ``z_CS4`` ... in mm, the paper's labels) and each gets the type-B standard
uncertainty of eq. (5) with E_L,MPE evaluated at its own length ``|x_i|``::

    u(x_i) = b * E_L,MPE(|x_i|) = b * (A_um + |x_i| / B_mm)        [µm]

The combined standard uncertainty is eq. (6), ``u_c = sqrt(sum((dl/dx_i * u(x_i))^2))``,
and ``U = k * u_c``.

Models (all with closed-form sensitivities of the cross/dot-product formulas):

===============  =============================================  ============  ========
model            distance                                       equations     variants
===============  =============================================  ============  ========
point_point      |AB|                                           (1)           1
point_line       |AS x AB| / |AB|                               (2)           2
point_plane      |AS . (AB x AC)| / |AB x AC|                   (3)           9
line_line        |AC . (AB x CD)| / |AB x CD|                   (4)           4
datum primary    |AS . u| / |u|,  u = AB x AC                   (7), (10-18)  9
datum secondary  |DS . v| / |v|,  v = DE x u                    (8), (27-32)  6
datum tertiary   |DS . w| / |w|,  w = u x (DE x u)              (9), (19-21)  3
position         POS = 2 sqrt((l1-l1TED)^2 + (l2-l2TED)^2)      (22)          product
===============  =============================================  ============  ========

A *variant* is one way of writing the same distance (another origin point, another pair of
edge vectors for the plane normal); the values agree, the uncertainties differ, and the
variant of lowest ``u_c`` is selected (paper, section 2).  ``variant="auto"`` does that;
exact ties go to the first variant in the paper's equation order.

Conventions (see docs/errata.md, "Wojtyła/Płowucha 2023"):

* Position uncertainty: ``u_POS = 2 sqrt(u_l1^2 + u_l2^2)``, which reproduces Table 9; it is the
  root-mean-square of the measured POS of a feature at its exact (TED) location, where the
  linearisation of eqs. (23)-(25) is undefined.  It is written as a budget with the two
  distances as inputs and sensitivity 2.
* A point exactly on a plane-type datum (``l = 0``): ``|.|`` has a kink, the one-sided
  derivative from the positive side is used (sign +1).  ``u_c`` is the same from both sides
  because only the signs of all sensitivities flip.  The paper instead moved the input by
  0.01 mm (Table 7), which the shipped knuckle task does through the point coordinates.
* Distances that vanish for a point on a *line* (point_line) or for coincident points
  (point_point) have no derivative (not even one-sided up to sign): DegenerateGeometryError.
  So do collinear plane points, parallel lines in line_line and a secondary-datum direction DE
  perpendicular to the primary plane.  A non-finite coordinate is a ModelError.

* The workpiece's temperature (the factor W, docs/workpiece.md): with a ``Part`` the budget gains
  the rows of alpha, T, the temperature difference across the part and the expansion the CMM
  leaves uncorrected, with sensitivities -l (T - 20) and -l alpha (x 10^-3 µm per 10^-6/K and per K:
  the corrected length is l_20 = l (1 - alpha (T - 20)), l the characteristic, which a uniform
  expansion scales as a whole) in the paper's layout; u_c is the root sum of squares of every row.
  The position's u_POS combines its two distances' u_l, W included.

The module is numpy only; it knows nothing of spreadsheets.  Each evaluated variant exposes
its ordered input vectors (label, tail point, head point, role in the formula), the input
quantities, their values, the closed-form sensitivities, ``u_i`` and contributions, so that a
workbook writer can lay out the same budget as cell formulas.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from .errors import DegenerateGeometryError, ModelError
from .model.workpiece import REFERENCE_C, Workpiece

#: relative threshold for a vanishing cross product (|a x c| <= EPS_REL |a||c|)
EPS_REL = 1e-12

AXES = ("x", "y", "z")

DATUMS = ("primary", "secondary", "tertiary")

#: structural kinds of a variant (the formula skeleton a workbook writer has to lay out)
KINDS = ("point_point", "point_line", "plane", "line_line", "secondary", "tertiary")


# --------------------------------------------------------------------------------------
# MPE and input uncertainties (eq. (5))
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MPE:
    """E_L,MPE = A_um + L/B_mm (µm, L in mm), distribution factor ``b`` (eq. (5); 0.577 for a
    uniform distribution) and coverage factor ``k`` for the expanded uncertainty."""

    A_um: float
    B_mm: float
    b: float
    k: float = 2.0

    def __post_init__(self) -> None:
        for name in ("A_um", "B_mm", "b", "k"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
                raise ModelError(f"{name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ModelError(f"{name} must be a finite number, got {value!r}")
        if self.A_um < 0:
            raise ModelError(f"A_um must not be negative, got {self.A_um!r}")
        if self.B_mm <= 0:
            raise ModelError(f"B_mm must be positive (E = A + L/B), got {self.B_mm!r}")
        if self.b <= 0:
            raise ModelError(f"b must be positive, got {self.b!r}")
        if self.k <= 0:
            raise ModelError(f"k must be positive, got {self.k!r}")

    def E_um(self, L_mm):
        """E_L,MPE(L) in µm."""
        return self.A_um + np.abs(L_mm) / self.B_mm

    def u_um(self, x_mm):
        """u(x_i) = b E_L,MPE(|x_i|) in µm (eq. (5) applied to one coordinate difference)."""
        return self.b * (self.A_um + np.abs(np.asarray(x_mm, dtype=float)) / self.B_mm)


# --------------------------------------------------------------------------------------
# Structure of a variant
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Vec:
    """One input vector: the coordinate difference ``head - tail`` (label ``tail+head``, e.g.
    ``CS4`` = S4 - C) and its role in the formula skeleton:

    ``p``  the vector whose projection is the distance (AS, DS1, AC in line_line, AB in
           point_point);
    ``a``, ``c``  the two edge vectors whose cross product is the normal (AB, AC; or the
           direction of the line in point_line (``a`` only); or AB, CD in line_line);
    ``d``  the secondary-datum direction DE.
    """

    tail: str
    head: str
    role: str

    @property
    def label(self) -> str:
        return f"{self.tail}{self.head}"

    @property
    def inputs(self) -> tuple[str, str, str]:
        return tuple(f"{ax}_{self.label}" for ax in AXES)


@dataclass(frozen=True)
class VariantSpec:
    """One formula variant: its skeleton ``kind``, its input vectors in the budget's row order
    and its label (the formula in ASCII: ``x`` cross, ``.`` dot)."""

    kind: str
    vectors: tuple[Vec, ...]
    label: str
    equation: str

    def vector(self, role: str) -> Vec:
        for v in self.vectors:
            if v.role == role:
                return v
        raise KeyError(role)

    @property
    def inputs(self) -> tuple[str, ...]:
        return tuple(name for v in self.vectors for name in v.inputs)


def _normal_vectors(A: str, B: str, C: str) -> list[tuple[Vec, Vec, str]]:
    """The three edge-vector pairs of the plane ABC: AB x AC, BA x BC, CA x CB (paper, eqs.
    (10)-(12)), with the text of the cross product."""
    out = []
    for o, q, r in ((A, B, C), (B, A, C), (C, A, B)):
        out.append((Vec(o, q, "a"), Vec(o, r, "c"), f"{o}{q}x{o}{r}"))
    return out


def variants_point_point(A: str, B: str) -> list[VariantSpec]:
    """Eq. (1): l = |AB| (one variant; BA has the same uncertainty)."""
    return [VariantSpec("point_point", (Vec(A, B, "p"),), f"|{A}{B}|", "eq. (1)")]


def variants_point_line(S: str, A: str, B: str) -> list[VariantSpec]:
    """Eq. (2): l = |AS x AB/|AB||, and the variant with BS instead of AS."""
    out = []
    for o in (A, B):
        out.append(VariantSpec("point_line", (Vec(o, S, "p"), Vec(A, B, "a")),
                               f"|{o}{S}x{A}{B}|/|{A}{B}|", "eq. (2)"))
    return out


def variants_point_plane(S: str, A: str, B: str, C: str, *, first_eq: int | None = None
                         ) -> list[VariantSpec]:
    """Eq. (3): l = |PS . n/|n||, P in {A, B, C}, n in {AB x AC, BA x BC, CA x CB}: 9 variants,
    in the order of eqs. (10)-(18) when used for the primary datum (``first_eq=10``)."""
    out = []
    i = 0
    for o in (A, B, C):
        for a, c, text in _normal_vectors(A, B, C):
            eq = f"eq. ({first_eq + i})" if first_eq else "eq. (3)"
            out.append(VariantSpec("plane", (Vec(o, S, "p"), a, c), f"{o}{S}.({text})", eq))
            i += 1
    return out


def variants_line_line(A: str, B: str, C: str, D: str) -> list[VariantSpec]:
    """Eq. (4): l = |PQ . (AB x CD)/|AB x CD||, PQ in {AC, BC, AD, BD}.  Rows in the order of
    the arguments of eq. (4): AB, CD, PQ."""
    out = []
    for o, h in ((A, C), (B, C), (A, D), (B, D)):
        out.append(VariantSpec("line_line", (Vec(A, B, "a"), Vec(C, D, "c"), Vec(o, h, "p")),
                               f"{o}{h}.({A}{B}x{C}{D})", "eq. (4)"))
    return out


@dataclass(frozen=True)
class DatumSystem:
    """Datum system of essential points (paper, section 3, eqs. (7)-(9)).

    primary    plane through ``primary`` = (A, B, C), normal u = AB x AC (or BA x BC, CA x CB);
    secondary  plane through D and E (``secondary`` = (D, E)) perpendicular to the primary,
               normal v = DE x u;
    tertiary   plane through ``tertiary_point`` (default D) perpendicular to both, normal
               w = u x v = u x (DE x u).
    """

    primary: tuple[str, str, str]
    secondary: tuple[str, str]
    tertiary_point: str | None = None

    def __post_init__(self) -> None:
        if len(self.primary) != 3 or len(set(self.primary)) != 3:
            raise ModelError(f"the primary datum needs 3 distinct points, got {list(self.primary)}")
        if len(self.secondary) != 2 or len(set(self.secondary)) != 2:
            raise ModelError(
                f"the secondary datum needs 2 distinct points, got {list(self.secondary)}")
        if self.tertiary_point is None:
            object.__setattr__(self, "tertiary_point", self.secondary[0])

    @property
    def points(self) -> tuple[str, ...]:
        out = list(self.primary) + list(self.secondary)
        if self.tertiary_point not in out:
            out.append(self.tertiary_point)
        return tuple(out)


def variants_datum(S: str, datum: str, ds: DatumSystem) -> list[VariantSpec]:
    """Distance of the point S from one datum of ``ds`` with all its variants:
    primary eqs. (10)-(18), secondary eqs. (27)-(32), tertiary eqs. (19)-(21) = (33)-(35)."""
    A, B, C = ds.primary
    D, E = ds.secondary
    if datum == "primary":
        return variants_point_plane(S, A, B, C, first_eq=10)
    if datum == "secondary":
        out = []
        i = 0
        for o in (D, E):
            for a, c, text in _normal_vectors(A, B, C):
                out.append(VariantSpec(
                    "secondary", (Vec(o, S, "p"), a, c, Vec(D, E, "d")),
                    f"{o}{S}.({D}{E}x({text}))", f"eq. ({27 + i})"))
                i += 1
        return out
    if datum == "tertiary":
        T = ds.tertiary_point
        out = []
        for i, (a, c, text) in enumerate(_normal_vectors(A, B, C)):
            out.append(VariantSpec(
                "tertiary", (Vec(T, S, "p"), a, c, Vec(D, E, "d")),
                f"{T}{S}.(({text})x({D}{E}x({text})))", f"eqs. ({19 + i}), ({33 + i})"))
        return out
    raise ModelError(f"datum must be one of {', '.join(DATUMS)}, got {datum!r}")


# --------------------------------------------------------------------------------------
# Closed-form values and sensitivities
# --------------------------------------------------------------------------------------


def _finite_vec(x, what: str) -> np.ndarray:
    v = np.asarray(x, dtype=float).reshape(-1)
    if v.shape != (3,):
        raise ModelError(f"{what} must have 3 coordinates, got {v.size}")
    if not np.all(np.isfinite(v)):
        raise ModelError(f"{what} has a non-finite coordinate: {v.tolist()}")
    return v


def _project(p: np.ndarray, n: np.ndarray):
    """l = |p . n/|n|| with its gradients: dl/dp = s n^ and g = dl/dn = s (p - (p.n^) n^)/|n|,
    where s = sign(p . n), taken +1 at p . n = 0 (one-sided derivative; u_c is the same from
    both sides)."""
    nn = math.sqrt(float(n @ n))
    nh = n / nn
    t = float(p @ nh)
    s = -1.0 if t < 0 else 1.0
    return s * t, s * nh, s * (p - t * nh) / nn


def _check_cross(a: np.ndarray, c: np.ndarray, n: np.ndarray, message: str) -> None:
    scale = math.sqrt(float(a @ a) * float(c @ c))
    if not scale > 0 or math.sqrt(float(n @ n)) <= EPS_REL * scale:
        raise DegenerateGeometryError(message)


def evaluate_vectors(kind: str, vecs: Mapping[str, np.ndarray], names: Mapping[str, str] | None = None):
    """Value ``l`` (mm) and gradients ``{role: dl/dvector}`` of a formula skeleton.

    ``vecs`` maps roles (``p``, ``a``, ``c``, ``d``) to 3-vectors of coordinate differences;
    ``names`` maps roles to labels for the error messages.
    """
    nm = {"p": "p", "a": "a", "c": "c", "d": "d"}
    if names:
        nm.update(names)
    p = vecs["p"] if "p" in vecs else None

    if kind == "point_point":
        L = math.sqrt(float(p @ p))
        if L == 0:
            raise DegenerateGeometryError(
                f"points of {nm['p']} coincide: the distance |{nm['p']}| = 0 is not differentiable")
        return L, {"p": p / L}

    if kind == "point_line":
        a = vecs["a"]
        aa = math.sqrt(float(a @ a))
        if aa == 0:
            raise DegenerateGeometryError(
                f"the line {nm['a']} is undefined: its two points coincide")
        m = np.cross(p, a)
        mm = math.sqrt(float(m @ m))
        pp = math.sqrt(float(p @ p))
        if mm <= EPS_REL * pp * aa:
            raise DegenerateGeometryError(
                f"the point of {nm['p']} lies on the line {nm['a']} (distance 0): eq. (2) is not "
                "differentiable there; move the point off the line or use a plane-type model")
        L = mm / aa
        return L, {"p": np.cross(a, m) / (mm * aa),
                   "a": np.cross(m, p) / (mm * aa) - mm * a / aa**3}

    a, c = vecs["a"], vecs["c"]
    u = np.cross(a, c)
    if kind == "plane":
        _check_cross(a, c, u, f"the plane points are collinear ({nm['a']} x {nm['c']} = 0): "
                     "the plane normal of eq. (3)/(7) is undefined")
        L, dp, g = _project(p, u)
        return L, {"p": dp, "a": np.cross(c, g), "c": np.cross(g, a)}

    if kind == "line_line":
        _check_cross(a, c, u, f"the lines {nm['a']} and {nm['c']} are parallel "
                     f"({nm['a']} x {nm['c']} = 0): eq. (4) is undefined; use point_line "
                     "(distance of a point of one line from the other)")
        L, dp, g = _project(p, u)
        return L, {"p": dp, "a": np.cross(c, g), "c": np.cross(g, a)}

    if kind in ("secondary", "tertiary"):
        d = vecs["d"]
        _check_cross(a, c, u, f"the primary datum points are collinear ({nm['a']} x {nm['c']} "
                     "= 0): the normal u of eq. (7) is undefined")
        v = np.cross(d, u)
        _check_cross(d, u, v, f"the secondary datum direction {nm['d']} is perpendicular to the "
                     f"primary datum ({nm['d']} x u = 0): eqs. (8)-(9) are undefined")
        if kind == "secondary":                 # eq. (8): v = DE x u
            L, dp, g = _project(p, v)
            dd = np.cross(u, g)                 # dl/dd through v = d x u
            gu = np.cross(g, d)                 # dl/du through v = d x u
        else:                                   # eq. (9): w = u x v, v = DE x u
            w = np.cross(u, v)
            L, dp, g = _project(p, w)
            gv = np.cross(g, u)                 # dl/dv through w = u x v
            dd = np.cross(u, gv)                # dl/dd through v = d x u
            gu = np.cross(v, g) + np.cross(gv, d)   # dl/du through w and through v
        return L, {"p": dp, "a": np.cross(c, gu), "c": np.cross(gu, a), "d": dd}

    raise ModelError(f"unknown formula kind {kind!r}")


@dataclass(frozen=True)
class Part:
    """The workpiece's thermal state and its standard uncertainties u(alpha) (10^-6/K), u(T) (K):
    the factor W of a budget (docs/workpiece.md)."""

    workpiece: Workpiece
    u_alpha_ppm_per_K: float
    u_T_K: float


#: the rows of the factor W in a budget: input, unit of its value, distribution
THERMAL_INPUTS = (("alpha", "ppm/K", "normal"), ("T", "degC", "normal"), ("dT", "K", "rectangular"),
                  ("b_uncorrected", "ppm", "uncorrected (RSS)"))


def thermal_rows(l_mm: float, part: Part) -> list[dict]:
    """The W rows of a budget of the characteristic l (docs/workpiece.md), each with its value (in
    ``unit``), sensitivity (µm per unit), u (in ``unit``) and contribution (µm): alpha with
    -l (T - 20) 10^-3 and u(alpha); T with -l alpha 10^-3 and u(T); the temperature difference dT
    across the part with -l alpha 10^-3 and dT/sqrt(12); the uncorrected expansion b with l 10^-3 and
    |b|.  With W switched off every u is 0 (the rows stay, as in the workbook)."""
    wp = part.workpiece
    on = 1.0 if wp.enabled else 0.0
    dt = wp.T_degC - REFERENCE_C
    b = wp.bias_ppm()
    vals = (wp.alpha_ppm_per_K, wp.T_degC, wp.dT_K, b)
    sens = (-l_mm * dt * 1e-3, -l_mm * wp.alpha_ppm_per_K * 1e-3, -l_mm * wp.alpha_ppm_per_K * 1e-3, l_mm * 1e-3)
    us = (part.u_alpha_ppm_per_K * on, part.u_T_K * on, wp.dT_K / math.sqrt(12.0) * on, abs(b) * on)
    return [{"input": name, "value": float(v), "unit": unit, "sensitivity": float(s), "u": float(u),
             "contribution_um": float(s * u), "distribution": dist}
            for (name, unit, dist), v, s, u in zip(THERMAL_INPUTS, vals, sens, us)]


@dataclass
class VariantBudget:
    """The budget of one variant in the paper's layout (Tables 1-8): per input quantity the
    value x_i (mm), dl/dx_i, u_i (µm) and the contribution dl/dx_i * u_i (µm); then u_c, U.
    ``thermal``: the rows of the factor W (:func:`thermal_rows`), in u_c too; ``u_mpe_um``, ``u_W_um``
    the two parts of u_c."""

    spec: VariantSpec
    inputs: tuple[str, ...]
    values_mm: np.ndarray
    sensitivities: np.ndarray
    u_um: np.ndarray
    contributions_um: np.ndarray
    value_mm: float
    u_c_um: float
    U_um: float
    thermal: list[dict] = field(default_factory=list)
    u_mpe_um: float = 0.0
    u_W_um: float = 0.0

    @property
    def label(self) -> str:
        return self.spec.label

    def rows(self) -> list[dict]:
        return [{"input": n, "value_mm": float(x), "sensitivity": float(s), "u_um": float(u),
                 "contribution_um": float(c)}
                for n, x, s, u, c in zip(self.inputs, self.values_mm, self.sensitivities,
                                         self.u_um, self.contributions_um)]


def _point(points: Mapping[str, Sequence[float]], name: str) -> np.ndarray:
    if name not in points:
        raise ModelError(f"unknown point {name!r} (known: {', '.join(points)})")
    return _finite_vec(points[name], f"point {name}")


def input_vectors(spec: VariantSpec, points: Mapping[str, Sequence[float]]) -> dict[str, np.ndarray]:
    """The coordinate differences (head - tail, mm) of a variant, by role."""
    return {v.role: _point(points, v.head) - _point(points, v.tail) for v in spec.vectors}


def evaluate(spec: VariantSpec, points: Mapping[str, Sequence[float]], mpe: MPE,
             part: Part | None = None) -> VariantBudget:
    """Evaluate one variant: value, closed-form sensitivities, u_i = b E(|x_i|) and u_c (eq. (6)),
    with the rows of the factor W when the task has a ``part``."""
    vecs = input_vectors(spec, points)
    L, grads = evaluate_vectors(spec.kind, vecs, {v.role: v.label for v in spec.vectors})
    values = np.concatenate([vecs[v.role] for v in spec.vectors])
    sens = np.concatenate([grads[v.role] for v in spec.vectors])
    u = mpe.u_um(values)
    contrib = sens * u
    thermal = thermal_rows(float(L), part) if part is not None else []
    tc = np.array([r["contribution_um"] for r in thermal])
    both = np.concatenate([contrib, tc])
    u_c = math.sqrt(float(both @ both))
    return VariantBudget(spec, spec.inputs, values, sens, u, contrib, float(L), u_c, mpe.k * u_c, thermal,
                         math.sqrt(float(contrib @ contrib)), math.sqrt(float(tc @ tc)))


def value_of(spec: VariantSpec, values_mm: np.ndarray) -> float:
    """The model value from the flat vector of input quantities (for numerical derivatives)."""
    x = np.asarray(values_mm, dtype=float).reshape(-1, 3)
    vecs = {v.role: x[i] for i, v in enumerate(spec.vectors)}
    return evaluate_vectors(spec.kind, vecs)[0]


# --------------------------------------------------------------------------------------
# Characteristics: distance with variant choice, position
# --------------------------------------------------------------------------------------


def _norm_label(text: str) -> str:
    t = str(text).replace("×", "x").replace("·", ".").replace("⋅", ".").replace("*", ".")
    return "".join(t.split())


@dataclass
class DistanceBudget:
    """A distance characteristic: all variants evaluated, and the one used (``chosen``)."""

    variants: list[VariantBudget]
    chosen: VariantBudget
    requested: str

    @property
    def value_mm(self) -> float:
        return self.chosen.value_mm

    @property
    def u_um(self) -> float:
        return self.chosen.u_c_um

    @property
    def U_um(self) -> float:
        return self.chosen.U_um


def choose(variants: Sequence[VariantBudget], variant: str = "auto", *, rtol: float = 1e-9
           ) -> VariantBudget:
    """``"auto"``: the variant of lowest u_c, ties (relative ``rtol``) to the first in the
    paper's order; otherwise the variant with that label (spaces, × and · tolerated)."""
    if variant is None or _norm_label(variant).lower() == "auto":
        best = min(v.u_c_um for v in variants)
        for v in variants:
            if v.u_c_um <= best * (1 + rtol):
                return v
    want = _norm_label(variant)
    for v in variants:
        if _norm_label(v.label) == want:
            return v
    raise ModelError(f"unknown variant {variant!r}; use \"auto\" or one of: "
                     + ", ".join(v.label for v in variants))


def distance_budget(specs: Sequence[VariantSpec], points: Mapping[str, Sequence[float]],
                    mpe: MPE, variant: str = "auto", part: Part | None = None) -> DistanceBudget:
    """Evaluate every variant and pick one (see :func:`choose`)."""
    budgets = [evaluate(s, points, mpe, part) for s in specs]
    return DistanceBudget(budgets, choose(budgets, variant), str(variant))


def specs_for(model: str, *, points_used: Mapping[str, object], datums: DatumSystem | None = None
              ) -> list[VariantSpec]:
    """Variants of a distance model from the point names it uses:

    point_point     ``from``, ``to``
    point_line      ``point``, ``line`` = (A, B)
    point_plane     ``point``, ``plane`` = (A, B, C)
    line_line       ``line1`` = (A, B), ``line2`` = (C, D)
    datum_distance  ``point``, ``datum`` (primary | secondary | tertiary) with ``datums``
    """
    g = points_used
    if model == "point_point":
        return variants_point_point(g["from"], g["to"])
    if model == "point_line":
        A, B = g["line"]
        return variants_point_line(g["point"], A, B)
    if model == "point_plane":
        A, B, C = g["plane"]
        return variants_point_plane(g["point"], A, B, C)
    if model == "line_line":
        A, B = g["line1"]
        C, D = g["line2"]
        return variants_line_line(A, B, C, D)
    if model == "datum_distance":
        if datums is None:
            raise ModelError("datum_distance needs a datum system")
        return variants_datum(g["point"], g["datum"], datums)
    raise ModelError(f"unknown distance model {model!r}")


@dataclass
class PositionBudget:
    """Position deviation with a cylindrical tolerance zone (eq. (22)) from two datum distances.

    ``u_um = 2 sqrt(u_l1^2 + u_l2^2)`` (the convention that reproduces Table 9; see module
    docstring): a budget whose inputs are l1 and l2 with sensitivity 2.  ``u_eq26_um`` is the
    paper's eq. (26) with u_l = max(u_l1, u_l2), for information.
    """

    point: str
    datums: tuple[str, str]
    ted_mm: tuple[float, float]
    distances: tuple[DistanceBudget, DistanceBudget]
    inputs: tuple[str, str]
    value_mm: float
    sensitivities: np.ndarray
    u_inputs_um: np.ndarray
    contributions_um: np.ndarray
    u_um: float
    U_um: float
    u_eq26_um: float

    @property
    def variant(self) -> str:
        return " | ".join(d.chosen.label for d in self.distances)

    def rows(self) -> list[dict]:
        return [{"input": n, "value_mm": d.value_mm, "sensitivity": float(s), "u_um": float(u),
                 "contribution_um": float(c)}
                for n, d, s, u, c in zip(self.inputs, self.distances, self.sensitivities,
                                         self.u_inputs_um, self.contributions_um)]


#: sensitivity of POS to each datum distance in the RMS convention (POS = 2|deviation|)
POSITION_FACTOR = 2.0


def position_budget(point: str, datums: Sequence[str], ted_mm: Sequence[float],
                    ds: DatumSystem, points: Mapping[str, Sequence[float]], mpe: MPE,
                    variants: Sequence[str] = ("auto", "auto"), part: Part | None = None) -> PositionBudget:
    """Position deviation of the axis point ``point`` (cylindrical zone, eq. (22)) from the two
    ``datums`` (e.g. ("primary", "tertiary")) with theoretically exact distances ``ted_mm``."""
    datums = tuple(datums)
    if len(datums) != 2 or datums[0] == datums[1] or any(d not in DATUMS for d in datums):
        raise ModelError(f"a position needs two different datums of {', '.join(DATUMS)}, "
                         f"got {list(datums)}")
    ted = tuple(float(t) for t in ted_mm)
    if len(ted) != 2 or not all(math.isfinite(t) for t in ted):
        raise ModelError(f"ted_mm must be two finite numbers, got {list(ted_mm)}")
    if isinstance(variants, str):
        variants = (variants, variants)
    if len(variants) != 2:
        raise ModelError(f"a position needs one variant per distance, got {list(variants)}")
    dist = tuple(distance_budget(variants_datum(point, d, ds), points, mpe, v, part)
                 for d, v in zip(datums, variants))
    dev = np.array([dist[0].value_mm - ted[0], dist[1].value_mm - ted[1]])
    value = 2.0 * math.sqrt(float(dev @ dev))
    u_in = np.array([d.u_um for d in dist])
    sens = np.array([POSITION_FACTOR, POSITION_FACTOR])
    contrib = sens * u_in
    u = math.sqrt(float(contrib @ contrib))
    return PositionBudget(point, datums, ted, dist, (f"l_{point},1", f"l_{point},2"), value,
                          sens, u_in, contrib, u, mpe.k * u, 2.0 * float(u_in.max()))
