"""Characteristics of a drawing from several least-squares features fitted in one task, with
their uncertainty under the full point-cloud variance V_X of one CMM (Forbes 2025 eq. (28)).

Features (Forbes 2022): every feature is fitted to its own points of one joint point set;
stacking their sensitivity matrices G_A|X (eq. (8)) row-wise gives the joint

    G = [G_1 (columns of the points of feature 1); G_2; ...]   (sum n_f) x 3m,
    V_A = G V_X G^T                                            (Forbes 2025 section 5.6),

whose off-diagonal blocks are the correlations between features measured by one CMM (scale,
squareness, the spatially correlated errors, a probe qualification shared by all points).

Characteristics (ISO 1101:2017 / ASME Y14.5-2018 names) are functions of the features' local
parameters a and, for form and for orientation zones of surfaces, of the extreme points
directly.  Each is linearised as

    delta c = s_A delta a + s_Xd delta x   ->   s_X = s_Xd + s_A G,   u^2(c) = s_X V_X s_X^T,

s_A by central differences through the features' geometry (xlfuncs.features.update_frame),
s_Xd over the coordinates of the points that decide the value (the contact points of a minimum
zone, the highest and lowest point of a peak-to-valley) with those points held fixed.  For the
smooth characteristics (size, distance, angle, orientation and position of axes) s_Xd = 0 and
u^2 = s_A V_A s_A^T -- the workbook's live MMULT.  Form values and zones of surfaces are maxima
over points: their u is the active-set linearisation; the Monte Carlo (:func:`monte_carlo`)
says how good it is.

Conventions (docs/characteristics.md): lengths in mm, angles in degrees; u in µm (lengths) or
µrad (angles).  The size of a feature of size is its least-squares diameter (not the ASME
actual mating envelope); position and axis orientation are evaluated at the ends of the axis
over the extent of the feature's points along the datum axis at the reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from . import features as ft
from .datums import AXIS, PLANE, Frame, Geometry, datum_frame, role
from .errors import ModelError
from .minzone import basis_is_optimal, chebyshev_zone

__all__ = [
    "FeatureSpec", "FrameSpec", "CharacteristicSpec", "JointFit", "Result", "TYPES",
    "fit_features", "joint_V_A", "evaluate", "monte_carlo", "FORM_TYPES", "SMOOTH_TYPES",
]

FORM_TYPES = ("flatness", "straightness", "roundness", "cylindricity")
ORIENTATION_TYPES = ("perpendicularity", "parallelism", "angularity")
SIZE_TYPES = ("diameter", "width", "cone_angle")
TYPES = SIZE_TYPES + ("distance", "angle") + FORM_TYPES + ORIENTATION_TYPES + ("position",)
#: the types whose value is a smooth function of the features' parameters only
SMOOTH_TYPES = SIZE_TYPES + ("distance", "angle", "position")
FORM_ELEMENT = {"flatness": ("plane",), "straightness": ("line",), "roundness": ("circle",),
                "cylindricity": ("cylinder",)}
#: the residual derivative columns that are free zone parameters (small-angle form): the
#: locating offset / radius column is absorbed by the zone limits
FREE_COLUMNS = {"plane": (1, 2), "circle": (0, 1), "cylinder": (0, 1, 2, 3)}
STEP = 1e-5          # central-difference step, mm or rad
RAD = math.pi / 180.0


# ------------------------------------------------------------------------------------------
# specifications
# ------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FeatureSpec:
    """A feature: ``element`` fitted to the points ``indices`` of the joint point set."""

    name: str
    element: str
    indices: tuple[int, ...]
    circle_plane: str | None = "xy"
    axis_hint: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class FrameSpec:
    """A datum reference frame A|B|C: feature names in order of precedence."""

    name: str
    primary: str
    secondary: str | None = None
    tertiary: str | None = None


@dataclass(frozen=True)
class CharacteristicSpec:
    """A characteristic of the drawing.

    ``type``: diameter (circle, cylinder, sphere), width (two planes), cone_angle (a cone's
    included angle 2 phi, deg), distance (locating point
    of the second feature to the first element), angle (between the two fitted directions --
    normals outward, axes as oriented -- 0 to 180 deg),
    flatness/straightness/roundness/cylindricity (``method`` "LS" peak-to-valley of the
    residuals to the least-squares feature, or "MZ" minimum zone), perpendicularity/parallelism/
    angularity (to the primary datum of ``frame``, or to the feature ``datum``; a plane's zone
    oriented by its least-squares normal, or with ``method`` "MZ" turned about the datum
    direction to its minimum; ``zone``
    "planar" for a surface, "diametral" for an axis; angularity's ``nominal`` angle in deg),
    position (of an axis or centre in ``frame``, at ``nominal_position_mm`` in frame
    coordinates, diametral zone; ``material_condition`` MMC/LMC with the bonus from the size
    characteristic ``size``; ``internal`` for a hole).
    ``direction``: straightness only, the zone direction (the surface's nominal normal).
    Tolerances are carried here, not decided (the build decides them: generator.decision):
    ``lsl``/``usl`` (size, distance, angle) or ``tolerance_mm`` (zone width of form,
    orientation, position).
    """

    name: str
    type: str
    features: tuple[str, ...]
    method: str = "LS"
    frame: str | None = None
    datum: str | None = None
    nominal: float | None = None
    nominal_position_mm: tuple[float, ...] | None = None
    zone: str = "planar"
    material_condition: str = "RFS"
    size: str | None = None
    internal: bool = True
    direction: tuple[float, float, float] | None = None
    lsl: float | None = None
    usl: float | None = None
    tolerance_mm: float | None = None


@dataclass
class JointFit:
    """The features of one task fitted to their points, and the joint G (module docstring)."""

    X_mm: np.ndarray
    normals: np.ndarray
    specs: dict[str, FeatureSpec]
    fits: dict[str, ft.FeatureFit]
    rows: dict[str, slice]
    G: np.ndarray
    param_names: tuple[str, ...]

    @property
    def n(self) -> int:
        return self.G.shape[0]

    @property
    def m(self) -> int:
        return self.X_mm.shape[0]


@dataclass
class Result:
    """A characteristic's value, sensitivities and uncertainty, with its tolerance carried.

    ``s_A``: d value / d (joint local parameters) (value unit per mm or rad); ``s_X``: d value
    / d coordinates (per mm), 3m interleaved; ``u`` in µm (lengths) or µrad (angles), per
    factor in ``u_factors``.  For position at MMC/LMC: ``bonus_mm`` (from the measured size),
    ``zone_mm`` = tolerance + bonus, ``margin_mm`` = zone - value and its ``u_margin_um``
    (size and position are correlated through V_X; both are in it).
    """

    spec: CharacteristicSpec
    value: float
    unit: str                       # "mm" or "deg"
    s_A: np.ndarray
    s_X: np.ndarray
    smooth: bool
    active: np.ndarray              # joint point indices that decide the value (form, zones)
    u: float = math.nan
    u_factors: dict[str, float] = field(default_factory=dict)
    bonus_mm: float | None = None
    zone_mm: float | None = None
    margin_mm: float | None = None
    s_X_margin: np.ndarray | None = None
    s_A_margin: np.ndarray | None = None
    u_margin_um: float | None = None
    zone_iterations: int | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def u_unit(self) -> str:
        return "um" if self.unit == "mm" else "urad"


# ------------------------------------------------------------------------------------------
# the joint fit
# ------------------------------------------------------------------------------------------

def fit_features(X_mm, normals, specs: Sequence[FeatureSpec]) -> JointFit:
    """Fit every feature to its points (Forbes 2022) and stack the G_A|X into the joint G."""
    X = np.asarray(X_mm, float)
    N = np.asarray(normals, float)
    m = X.shape[0]
    if N.shape != X.shape:
        raise ModelError("normals must have the same shape as the points")
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise ModelError("feature names must be unique")
    fits, rows, blocks, pnames = {}, {}, [], []
    r0 = 0
    for s in specs:
        idx = np.asarray(s.indices, int)
        if idx.size == 0 or idx.min() < 0 or idx.max() >= m:
            raise ModelError(f"feature {s.name}: point indices out of range")
        if len(set(idx.tolist())) != idx.size:
            raise ModelError(f"feature {s.name}: a point is listed twice")
        try:
            f = ft.fit(s.element, X[idx], normals=N[idx], axis_hint=s.axis_hint,
                       circle_plane=s.circle_plane if s.element == "circle" else "xy")
        except ModelError as err:
            raise type(err)(f"feature {s.name}: {err}") from None
        Gf = ft.G_A_X(f)
        Gj = np.zeros((f.n, 3 * m))
        cols = (3 * idx[:, None] + np.arange(3)).reshape(-1)
        Gj[:, cols] = Gf
        fits[s.name] = f
        rows[s.name] = slice(r0, r0 + f.n)
        r0 += f.n
        blocks.append(Gj)
        pnames += [f"{s.name}.{p}" for p in f.local_names]
    return JointFit(X_mm=X, normals=N, specs={s.name: s for s in specs}, fits=fits, rows=rows,
                    G=np.vstack(blocks), param_names=tuple(pnames))


def joint_V_A(jf: JointFit, V_X_um2: Mapping[str, np.ndarray] | np.ndarray) -> dict[str, np.ndarray]:
    """V_A = G V_X G^T of all features' local parameters (mm, rad), per factor and "total"."""
    comps = {"V_X": V_X_um2} if isinstance(V_X_um2, np.ndarray) else dict(V_X_um2)
    out, total = {}, np.zeros((jf.n, jf.n))
    for k, V in comps.items():
        V = np.asarray(V, float)
        if V.shape != (3 * jf.m, 3 * jf.m):
            raise ModelError(f"V_X component {k}: expected {3 * jf.m} x {3 * jf.m}")
        Va = jf.G @ V @ jf.G.T * ft.UM2_TO_MM2
        out[k] = 0.5 * (Va + Va.T)
        total = total + out[k]
    out["total"] = total
    return out


# ------------------------------------------------------------------------------------------
# geometry of (perturbed) features, batched
# ------------------------------------------------------------------------------------------

def _geometry(f: ft.FeatureFit, delta=None, B: int = 1) -> Geometry:
    """The feature moved by local parameter changes delta (B x n): xlfuncs.features.update_frame."""
    if delta is None:
        o = np.broadcast_to(f.origin_mm, (B, 3)).copy()
        R = np.broadcast_to(f.R, (B, 3, 3)).copy()
        sh = np.broadcast_to(np.asarray(f.shape, float), (B, len(f.shape))).copy()
    else:
        o, R, sh = ft.update_frame(f.kind, f.origin_mm, f.R, f.shape, delta)
        if o.shape[0] != B:       # one change for a batch of point sets
            o, R = np.broadcast_to(o, (B, 3)), np.broadcast_to(R, (B, 3, 3))
            sh = np.broadcast_to(sh, (B, sh.shape[1]))
    return Geometry(element=f.element, kind=f.kind, point=o, R=R, shape=sh)


class _Context:
    """Batched geometry of every feature and the points (B draws or perturbations)."""

    def __init__(self, jf: JointFit, frames: Mapping[str, FrameSpec], deltas=None, X=None,
                 B: int = 1):
        self.jf, self.frame_specs, self.B = jf, frames, B
        self.deltas = deltas or {}
        self.X = jf.X_mm[None] if X is None else X
        self._g: dict[str, Geometry] = {}
        self._frames: dict[str, Frame] = {}

    def geom(self, name: str) -> Geometry:
        if name not in self._g:
            self._g[name] = _geometry(self.jf.fits[name], self.deltas.get(name), self.B)
        return self._g[name]

    def frame(self, name: str) -> Frame:
        if name not in self._frames:
            s = self.frame_specs[name]
            self._frames[name] = datum_frame(
                self.geom(s.primary), self.geom(s.secondary) if s.secondary else None,
                self.geom(s.tertiary) if s.tertiary else None)
        return self._frames[name]

    def points(self, name: str) -> np.ndarray:
        """(B or 1) x m_f x 3."""
        return self.X[:, np.asarray(self.jf.specs[name].indices, int)]


# ------------------------------------------------------------------------------------------
# the characteristics: value(ctx, spec, consts, frozen) -> (values (B,), frozen)
# ------------------------------------------------------------------------------------------

def _dot(a, b):
    return np.einsum("bi,bi->b", a, b)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _perp_unit(v, ref, fallback):
    """v made orthogonal to ref and normalised; where v is along ref, the fallback."""
    t = v - _dot(v, ref)[:, None] * ref
    n = np.linalg.norm(t, axis=-1, keepdims=True)
    return np.where(n > 1e-12, t / np.where(n > 0, n, 1.0), fallback)


def _size(ctx, c, consts, frozen):
    if c.type == "cone_angle":
        g = ctx.geom(c.features[0])
        if g.kind != "cone":
            raise ModelError(f"{c.name}: a cone angle needs a cone, not {g.kind}")
        return 2.0 * np.degrees(np.abs(g.shape[:, 1])), frozen
    if c.type == "diameter":
        g = ctx.geom(c.features[0])
        if g.kind not in ("circle", "circle_space", "cylinder", "sphere"):
            raise ModelError(f"{c.name}: a diameter needs a circle, cylinder or sphere, not {g.kind}")
        return 2.0 * g.shape[:, 0], frozen
    g1, g2 = ctx.geom(c.features[0]), ctx.geom(c.features[1])
    if g1.kind != "plane" or g2.kind != "plane":
        raise ModelError(f"{c.name}: a width needs two planes")
    a = np.abs(_dot(g1.direction, g2.point - g1.point))
    b = np.abs(_dot(g2.direction, g1.point - g2.point))
    return 0.5 * (a + b), frozen


def _distance(ctx, c, consts, frozen):
    g1, g2 = ctx.geom(c.features[0]), ctx.geom(c.features[1])
    q = g2.point - g1.point
    r = role(g1)
    if r == PLANE:
        return np.abs(_dot(g1.direction, q)), frozen
    if r == AXIS or (g1.kind == "circle" and g2.kind == "circle"):
        v = g1.direction
        return np.linalg.norm(q - _dot(q, v)[:, None] * v, axis=-1), frozen
    return np.linalg.norm(q, axis=-1), frozen


def _angle(ctx, c, consts, frozen):
    v1, v2 = ctx.geom(c.features[0]).direction, ctx.geom(c.features[1]).direction
    if v1 is None or v2 is None:
        raise ModelError(f"{c.name}: an angle needs two features with a direction")
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(v1, v2), axis=-1), _dot(v1, v2))), frozen


def _form_residuals(ctx, c):
    """(d (B x m_f), g (B x m_f x k)) of the form feature's points in its (batched) geometry."""
    name = c.features[0]
    g = ctx.geom(name)
    P = ctx.points(name)
    Q = P - g.point[:, None, :]
    if c.type == "straightness":
        v = g.direction
        n = _unit(np.broadcast_to(np.asarray(c.direction, float), v.shape))
        n = _unit(n - _dot(n, v)[:, None] * v)
        return np.einsum("bmi,bi->bm", Q, n), np.einsum("bmi,bi->bm", Q, v)[:, :, None]
    Pl = np.einsum("bmi,bij->bmj", Q, g.R)
    shape = () if g.kind == "plane" else (g.shape[:, 0:1],)
    d, J, _ = ft.local_model(g.kind, Pl, shape)
    return d[:, :, 0], -J[:, :, 0, list(FREE_COLUMNS[g.kind])]


def _extremes(h):
    """Peak-to-valley of h (B x m) and the weights +1 at the maximum, -1 at the minimum."""
    i, j = np.argmax(h, axis=1), np.argmin(h, axis=1)
    b = np.arange(h.shape[0])
    w = np.zeros(h.shape[1])
    w[i[0]] += 1.0
    w[j[0]] -= 1.0
    return h[b, i] - h[b, j], {"w": w}


def _form(ctx, c, consts, frozen):
    el = ctx.jf.fits[c.features[0]].element
    if el not in FORM_ELEMENT[c.type]:
        raise ModelError(f"{c.name}: {c.type} needs a {FORM_ELEMENT[c.type][0]} feature, not {el}")
    if c.type == "straightness" and c.direction is None:
        raise ModelError(f"{c.name}: straightness needs the zone direction (the surface's normal)")
    if c.type == "roundness" and ctx.jf.fits[c.features[0]].kind != "circle":
        raise ModelError(f"{c.name}: roundness needs a circle in a coordinate plane")
    if frozen is not None and "delta" in frozen:
        # the minimum zone's own (iterated) feature: the contact weights belong to it
        name = c.features[0]
        base = ctx.deltas.get(name)
        delta = frozen["delta"] if base is None else base + frozen["delta"]
        ctx = _Context(ctx.jf, ctx.frame_specs, deltas={name: delta}, X=ctx.X, B=ctx.B)
    d, g = _form_residuals(ctx, c)
    if frozen is not None:
        return d @ frozen["w"], frozen
    if c.method == "LS":
        return _extremes(d)
    zone = chebyshev_zone(d[0], g[0], basis=consts.get("basis"))
    return np.array([zone.h]), {"w": zone.w, "zone": zone}


def _mz_exact(ctx, c, consts):
    """The minimum zone iterated to the exact (not small-angle) zone: the feature is moved by
    the LP's p and the LP solved again until p is below 1e-12 (mm, rad)."""
    name = c.features[0]
    f = ctx.jf.fits[name]
    free = FREE_COLUMNS.get(f.kind)
    if c.type == "straightness" or free is None:
        return _form(ctx, c, consts, None)
    delta = np.zeros((1, f.n))
    basis, its = None, 0
    for _ in range(20):
        sub = _Context(ctx.jf, ctx.frame_specs, deltas={name: delta}, X=ctx.X)
        d, g = _form_residuals(sub, c)
        zone = chebyshev_zone(d[0], g[0], basis=basis)
        basis, its = zone.basis, its + zone.iterations
        if np.max(np.abs(zone.p)) <= 1e-12:
            break
        delta = delta.copy()
        delta[0, list(free)] += zone.p
    return np.array([zone.h]), {"w": zone.w, "zone": zone, "iterations": its, "delta": delta}


def _datum_direction(ctx, c):
    """The datum direction the zone is oriented to: the frame's z (into the material from the
    primary plane), or the datum feature's axis / inward normal."""
    if c.datum is not None:
        gd = ctx.geom(c.datum)
        if gd.direction is None:
            raise ModelError(f"{c.name}: the datum {c.datum} has no direction")
        return (gd.direction if role(gd) != PLANE else -gd.direction), role(gd) == PLANE
    if c.frame is None:
        raise ModelError(f"{c.name}: {c.type} needs a datum frame or a datum feature")
    return ctx.frame(c.frame).R[:, :, 2], True


def _alpha(c):
    if c.type == "parallelism":
        return 0.0
    if c.type == "perpendicularity":
        return 90.0
    if c.nominal is None:
        raise ModelError(f"{c.name}: angularity needs the nominal angle (deg)")
    return float(c.nominal)


def _orientation(ctx, c, consts, frozen):
    """ISO 1101 18.9-18.11: the zone at the nominal angle alpha to the datum (0 parallel, 90
    perpendicular), its own orientation about the datum taken from the feature's least-squares
    direction (``method`` "MZ": turned about the datum direction to the minimum zone).  A plane:
    the points' extent along the zone normal (form included).  An axis:
    the axis segment over the points' extent -- diametral zone: its length projected orthogonal
    to the zone axis; planar zone: along the zone normal."""
    g = ctx.geom(c.features[0])
    zd, datum_plane = _datum_direction(ctx, c)
    a = _alpha(c) * RAD
    v = g.direction
    # t: the direction of the feature's tilt from the datum direction (where there is none, the
    # frame's x axis, or any direction orthogonal to the datum)
    if c.frame:
        fallback = ctx.frame(c.frame).R[:, :, 0]
    else:
        helper = np.array([0.0, 0.0, 1.0]) if abs(zd[0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        fallback = _unit(np.cross(zd, helper))
    t = _perp_unit(v, zd, fallback)
    # the zone's normal (planar) makes alpha with a datum plane's normal ...
    e = (np.cos(a) * zd + np.sin(a) * t) if datum_plane else (np.sin(a) * zd + np.cos(a) * t)
    if role(g) == PLANE:
        pts = ctx.points(c.features[0])
        if frozen is not None:
            if "phi" in frozen:
                e = _rotate(e, zd, frozen["phi"])
            return np.einsum("bmi,bi->bm", pts, e) @ frozen["w"], frozen
        if c.method == "MZ":
            return _orientation_zone(pts, e, zd)
        return _extremes(np.einsum("bmi,bi->bm", pts, e))
    if role(g) != AXIS:
        raise ModelError(f"{c.name}: {c.type} needs a plane or an axis feature")
    L = consts["length_mm"]
    if c.zone == "diametral":
        # ... and the zone's axis makes 90 - alpha with it (alpha with a datum axis)
        za = (np.sin(a) * zd + np.cos(a) * t) if datum_plane else (np.cos(a) * zd + np.sin(a) * t)
        return L * np.linalg.norm(v - _dot(v, za)[:, None] * za, axis=-1), frozen
    return L * np.abs(_dot(v, e)), frozen


def _rotate(e, axis, phi):
    """e (B x 3) rotated by phi about the unit axis (B x 3) (Rodrigues)."""
    c, s = np.cos(phi), np.sin(phi)
    return e * c + np.cross(axis, e) * s + axis * (_dot(axis, e) * (1 - c))[:, None]


def _orientation_zone(pts, e, zd):
    """Minimum zone of a plane's points with the orientation constraint (ISO 1101: the zone at
    the nominal angle to the datum, free to turn about the datum direction): the small-angle LP
    in the one rotation phi about zd (h_i(phi) = x_i.e + phi x_i.(zd x e)), iterated to the
    exact rotation for the reference (B = 1), one LP per draw otherwise.  Where the zone cannot
    turn (parallelism to a plane: e = zd) it is the peak-to-valley."""
    B = max(pts.shape[0], e.shape[0])
    pts = np.broadcast_to(pts, (B,) + pts.shape[1:])
    e = np.broadcast_to(e, (B, 3))
    zd = np.broadcast_to(zd, (B, 3))
    if np.all(np.linalg.norm(np.cross(zd, e), axis=1) < 1e-12):
        return _extremes(np.einsum("bmi,bi->bm", pts, e))
    vals = np.empty(B)
    out = None
    for b in range(B):
        eb, zb, phi = e[b:b + 1], zd[b:b + 1], 0.0
        for _ in range(20 if B == 1 else 1):
            er = _rotate(eb, zb, phi)
            d = pts[b] @ er[0]
            g = -(pts[b] @ np.cross(zb, er)[0])[:, None]
            zone = chebyshev_zone(d, g)
            phi += float(zone.p[0])
            if abs(zone.p[0]) <= 1e-12:
                break
        vals[b] = zone.h
        if b == 0:
            out = {"w": zone.w, "phi": phi}
    return vals, out


def _position(ctx, c, consts, frozen):
    """ASME Y14.5 10.3 / ISO 1101 18.12: twice the largest distance of the feature's axis (at
    the two ends of its extent along the frame's z) or centre from the true position (frame
    coordinates), a diametral zone."""
    if c.frame is None or c.nominal_position_mm is None:
        raise ModelError(f"{c.name}: position needs a datum frame and the nominal position")
    F = ctx.frame(c.frame)
    g = ctx.geom(c.features[0])
    nom = np.asarray(c.nominal_position_mm, float)
    q = F.to_frame(g.point[:, None, :])[:, 0]
    r = role(g)
    if r == AXIS:
        v = F.direction(g.direction)
        devs = []
        for z in consts["heights_mm"]:
            p = q + ((z - q[:, 2]) / v[:, 2])[:, None] * v
            devs.append(np.hypot(p[:, 0] - nom[0], p[:, 1] - nom[1]))
        devs = np.stack(devs, axis=1)
        if frozen is not None:
            return 2.0 * devs[:, frozen["end"]], frozen
        return 2.0 * devs.max(axis=1), {"end": int(np.argmax(devs[0]))}
    if g.kind == "sphere":
        return 2.0 * np.linalg.norm(q - nom[:3], axis=-1), frozen
    return 2.0 * np.hypot(q[:, 0] - nom[0], q[:, 1] - nom[1]), frozen


_VALUE = {"diameter": _size, "width": _size, "cone_angle": _size, "distance": _distance, "angle": _angle,
          "flatness": _form, "straightness": _form, "roundness": _form, "cylindricity": _form,
          "perpendicularity": _orientation, "parallelism": _orientation,
          "angularity": _orientation, "position": _position}


def _constants(jf: JointFit, frames, c: CharacteristicSpec) -> dict:
    """What is fixed at the reference: an axis's length over its points, a position's heights."""
    ctx = _Context(jf, frames)
    out: dict = {}
    if c.type in ORIENTATION_TYPES or c.type == "position":
        g = ctx.geom(c.features[0])
        if role(g) == AXIS:
            P = ctx.points(c.features[0])[0]
            t = (P - g.point[0]) @ g.direction[0]
            out["length_mm"] = float(t.max() - t.min())
            if c.type == "position":
                zs = ctx.frame(c.frame).to_frame(P[None])[0, :, 2]
                out["heights_mm"] = (float(zs.min()), float(zs.max()))
    return out


def _check(c: CharacteristicSpec, jf: JointFit, frames) -> None:
    if c.type not in TYPES:
        raise ModelError(f"characteristic {c.name}: unknown type {c.type!r}; known: {', '.join(TYPES)}")
    need = 2 if c.type in ("width", "distance", "angle") else 1
    if len(c.features) != need:
        raise ModelError(f"characteristic {c.name}: {c.type} needs {need} feature(s)")
    for f in c.features + ((c.datum,) if c.datum else ()):
        if f not in jf.fits:
            raise ModelError(f"characteristic {c.name}: unknown feature {f!r}")
    if c.frame is not None and c.frame not in frames:
        raise ModelError(f"characteristic {c.name}: unknown datum frame {c.frame!r}")
    if c.method not in ("LS", "MZ"):
        raise ModelError(f"characteristic {c.name}: method must be LS or MZ")
    if c.material_condition not in ("RFS", "MMC", "LMC"):
        raise ModelError(f"characteristic {c.name}: material condition must be RFS, MMC or LMC")
    if c.zone not in ("planar", "diametral"):
        raise ModelError(f"characteristic {c.name}: zone must be planar or diametral")


# ------------------------------------------------------------------------------------------
# evaluation with sensitivities
# ------------------------------------------------------------------------------------------

def _point_columns(jf: JointFit, name: str, local: np.ndarray) -> np.ndarray:
    return np.asarray(jf.specs[name].indices, int)[local]


def _sensitivities(jf, frames, c, consts, frozen):
    """(s_A, s_Xd) by central differences with the active set held (module docstring), all
    perturbations in one batch."""
    fn = _VALUE[c.type]
    n = jf.n
    deltas = {}
    for name, sl in jf.rows.items():
        d = np.zeros((2 * n, sl.stop - sl.start))
        j = np.arange(sl.start, sl.stop)
        d[j, j - sl.start] = STEP
        d[n + j, j - sl.start] = -STEP
        deltas[name] = d
    v, _ = fn(_Context(jf, frames, deltas=deltas, B=2 * n), c, consts, frozen)
    s_A = (v[:n] - v[n:]) / (2 * STEP)
    # central-difference rounding of parameters the value does not depend on: exactly zero
    s_A[np.abs(s_A) <= 1e-9 * np.abs(s_A).max(initial=0.0)] = 0.0
    s_Xd = np.zeros(3 * jf.m)
    if frozen is not None and "w" in frozen:
        cols = _point_columns(jf, c.features[0], np.flatnonzero(frozen["w"]))
        k = 3 * cols.size
        if k:
            Xb = np.repeat(jf.X_mm[None], 2 * k, axis=0)
            for q, i in enumerate(cols):
                for a in range(3):
                    Xb[3 * q + a, i, a] += STEP
                    Xb[k + 3 * q + a, i, a] -= STEP
            v, _ = fn(_Context(jf, frames, X=Xb, B=2 * k), c, consts, frozen)
            dv = (v[:k] - v[k:]) / (2 * STEP)
            for q, i in enumerate(cols):
                s_Xd[3 * i:3 * i + 3] = dv[3 * q:3 * q + 3]
    return s_A, s_Xd


def _bonus(c: CharacteristicSpec, by_name: dict) -> tuple[float, np.ndarray, np.ndarray] | None:
    """Bonus tolerance from the measured size (ASME Y14.5-2018 5.8.1): MMC of a hole is its
    lower size limit, of a pin the upper; LMC the other way round.  Bonus = |size - size at the
    material condition|, clipped at 0 (a size beyond the MMC limit gets no bonus)."""
    if c.material_condition == "RFS":
        return None
    if c.size is None or c.size not in by_name:
        raise ModelError(f"characteristic {c.name}: {c.material_condition} needs the size "
                         f"characteristic of its feature (size = ...)")
    s = by_name[c.size]
    if s.spec.lsl is None or s.spec.usl is None:
        raise ModelError(f"characteristic {c.name}: the size {c.size} needs lsl and usl")
    mmc = c.material_condition == "MMC"
    lim = (s.spec.lsl if c.internal else s.spec.usl) if mmc else (s.spec.usl if c.internal else s.spec.lsl)
    sign = (1.0 if c.internal else -1.0) * (1.0 if mmc else -1.0)
    b = sign * (s.value - lim)
    if b <= 0:
        return 0.0, np.zeros_like(s.s_X), np.zeros_like(s.s_A)
    return b, sign * s.s_X, sign * s.s_A


def evaluate(jf: JointFit, frames: Sequence[FrameSpec] | Mapping[str, FrameSpec],
             chars: Sequence[CharacteristicSpec],
             V_X_um2: Mapping[str, np.ndarray] | np.ndarray | None = None) -> list[Result]:
    """Every characteristic's value and sensitivities; with V_X (per factor or total, µm²)
    also its u.  Size characteristics are evaluated before the positions that take a bonus
    from them."""
    frames = frames if isinstance(frames, Mapping) else {f.name: f for f in frames}
    for fs in frames.values():
        for nm in (fs.primary, fs.secondary, fs.tertiary):
            if nm is not None and nm not in jf.fits:
                raise ModelError(f"datum frame {fs.name}: unknown feature {nm!r}")
    order = sorted(range(len(chars)), key=lambda i: chars[i].type != "diameter")
    results: dict[int, Result] = {}
    by_name: dict[str, Result] = {}
    for i in order:
        c = chars[i]
        _check(c, jf, frames)
        consts = _constants(jf, frames, c)
        ctx = _Context(jf, frames)
        its = None
        if c.type in FORM_TYPES and c.method == "MZ":
            value, frozen = _mz_exact(ctx, c, consts)
            its = frozen.get("iterations")
        else:
            value, frozen = _VALUE[c.type](ctx, c, consts, None)
        value = float(value[0])
        s_A, s_Xd = _sensitivities(jf, frames, c, consts, frozen)
        s_X = s_Xd + s_A @ jf.G
        active = np.array([], int)
        if frozen is not None and "w" in frozen:
            active = _point_columns(jf, c.features[0], np.flatnonzero(frozen["w"]))
        res = Result(spec=c, value=value, unit="deg" if c.type in ("angle", "cone_angle") else "mm",
                     s_A=s_A,
                     s_X=s_X, smooth=c.type in SMOOTH_TYPES or (
                         c.type in ORIENTATION_TYPES and role(ctx.geom(c.features[0])) == AXIS),
                     active=active, zone_iterations=its)
        if c.type == "position":
            res.bonus_mm = 0.0
            bonus = _bonus(c, by_name)
            if bonus is not None:
                res.bonus_mm = bonus[0]
            if c.tolerance_mm is not None:
                res.zone_mm = c.tolerance_mm + res.bonus_mm
                res.margin_mm = res.zone_mm - value
                sb_X = bonus[1] if bonus else np.zeros_like(s_X)
                sb_A = bonus[2] if bonus else np.zeros_like(s_A)
                res.s_X_margin = sb_X - s_X
                res.s_A_margin = sb_A - s_A
        results[i] = res
        by_name[c.name] = res
    out = [results[i] for i in range(len(chars))]
    if V_X_um2 is not None:
        propagate(out, V_X_um2)
    return out


def propagate(results: Sequence[Result], V_X_um2) -> None:
    """u of every result (and of a position's margin) from V_X, per factor and total:
    u^2 = s_X V_X s_X^T (µm^2 for lengths; angles converted to µrad)."""
    comps = {"V_X": V_X_um2} if isinstance(V_X_um2, np.ndarray) else dict(V_X_um2)
    for r in results:
        conv = 1.0 if r.unit == "mm" else RAD * 1e6 * 1e-3   # deg/mm * µm -> µrad
        tot = 0.0
        for k, V in comps.items():
            v2 = float(r.s_X @ V @ r.s_X)
            r.u_factors[k] = math.sqrt(max(v2, 0.0)) * conv
            tot += v2
        r.u = math.sqrt(max(tot, 0.0)) * conv
        if r.s_X_margin is not None:
            tot = sum(float(r.s_X_margin @ V @ r.s_X_margin) for V in comps.values())
            r.u_margin_um = math.sqrt(max(tot, 0.0))


# ------------------------------------------------------------------------------------------
# Monte Carlo (JCGM 101) of every characteristic: refit, re-evaluate exactly
# ------------------------------------------------------------------------------------------

def monte_carlo(jf: JointFit, frames, chars: Sequence[CharacteristicSpec], results: Sequence[Result],
                cloud, params, *, n_dig: int = 2, batch: int = 2000, max_draws: int = 400_000,
                rng=None, sampler=None):
    """JCGM 101 adaptive Monte Carlo of the characteristics: every draw of the six influence
    factors (xlfuncs.montecarlo.PointCloudSampler over the joint point set) moves the points,
    every feature is refitted (Gauss-Newton from the reference, xlfuncs.montecarlo.refit_batch)
    and every characteristic evaluated anew: the extreme points found again, the minimum zone
    solved again (small-angle LP about the draw's least-squares feature, warm-started from the
    reference's contact points).  Returns the MCResult, u in the results' units (µm, µrad), then
    the margin (zone - value, µm) of every position with a tolerance, its MMC/LMC bonus taken
    from the drawn size."""
    from . import montecarlo as mc

    frames = frames if isinstance(frames, Mapping) else {f.name: f for f in frames}
    sampler = sampler or mc.PointCloudSampler(cloud, params)
    consts = [_constants(jf, frames, c) for c in chars]
    ref_basis = []
    for ci, c in enumerate(chars):
        if c.type in FORM_TYPES and c.method == "MZ":
            _, fz = _form(_Context(jf, frames), c, consts[ci], None)
            ref_basis.append(fz["zone"].basis)
        else:
            ref_basis.append(None)
    ref_local = {nm: mc.refit_batch(f, f.X_mm[None])[0] for nm, f in jf.fits.items()}
    ref_values = np.array([_VALUE[c.type](_Context(jf, frames), c, consts[ci], None)[0][0]
                           if ref_basis[ci] is None else
                           _form(_Context(jf, frames), c, consts[ci], None)[0][0]
                           for ci, c in enumerate(chars)])
    conv = np.array([1e3 if r.unit == "mm" else RAD * 1e6 for r in results])

    def one_batch(M, g):
        out = np.zeros((M, len(chars)))
        for s0 in range(0, M, 1000):
            Mb = min(1000, M - s0)
            dl = sum(sampler.draw(Mb, g).values())          # (Mb, m, 3) µm
            Xb = jf.X_mm[None] + dl * mc.MILLI
            deltas = {nm: mc.refit_batch(f, Xb[:, np.asarray(jf.specs[nm].indices, int)])
                      - ref_local[nm] for nm, f in jf.fits.items()}
            ctx = _Context(jf, frames, deltas=deltas, X=Xb, B=Mb)
            for ci, c in enumerate(chars):
                if ref_basis[ci] is None:
                    out[s0:s0 + Mb, ci] = _VALUE[c.type](ctx, c, consts[ci], None)[0]
                    continue
                # minimum zone: the reference contact points checked in one go, LP where changed
                ds, gs = _form_residuals(ctx, c)
                ok, h, _ = basis_is_optimal(ds, gs, ref_basis[ci])
                for b in np.flatnonzero(~ok):
                    h[b] = chebyshev_zone(ds[b], gs[b], basis=ref_basis[ci]).h
                out[s0:s0 + Mb, ci] = h
        cols = [(out - ref_values) * conv]
        for ci, si, sign, lim in margins:      # zone - value, the bonus from the drawn size
            bonus = np.clip(sign * (out[:, si] - lim), 0.0, None)
            cols.append(((chars[ci].tolerance_mm + bonus - out[:, ci]) - ref_margin[ci])[:, None] * 1e3)
        return {"total": np.hstack(cols)}

    # the margins of positions with a tolerance (MMC/LMC bonus from the size characteristic)
    by_name = {c.name: i for i, c in enumerate(chars)}
    margins = []
    for ci, (c, r) in enumerate(zip(chars, results)):
        if c.type != "position" or c.tolerance_mm is None:
            continue
        if c.material_condition == "RFS":
            margins.append((ci, ci, 0.0, 0.0))
            continue
        size = chars[by_name[c.size]]
        mmc = c.material_condition == "MMC"
        lim = (size.lsl if c.internal else size.usl) if mmc else (size.usl if c.internal else size.lsl)
        margins.append((ci, by_name[c.size], (1.0 if c.internal else -1.0) * (1.0 if mmc else -1.0), lim))
    ref_margin = {ci: c.tolerance_mm + max(0.0, sign * (ref_values[si] - lim)) - ref_values[ci]
                  for ci, si, sign, lim in margins for c in [chars[ci]]}

    names = [c.name for c in chars] + [f"{chars[ci].name} margin" for ci, *_ in margins]
    return mc.adaptive(one_batch, names, n_dig=n_dig, batch=batch, max_draws=max_draws, rng=rng)
