"""The value, sensitivities and uncertainty of every characteristic of a joint fit: each
characteristic linearised as delta c = s_A delta a + s_Xd delta x, s_X = s_Xd + s_A G,
u^2(c) = s_X V_X s_X^T (Forbes 2025 eq. (28) for V_X; the method in the package docstring,
:mod:`xlfuncs.characteristics`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from .. import features as ft
from ..datums import AXIS, PLANE, Frame, Geometry, datum_frame, role
from ..errors import ModelError, about
from ..minzone import chebyshev_zone
from .joint import JointFit
from .specs import FORM_TYPES, ORIENTATION_TYPES, SMOOTH_TYPES, TYPES, CharacteristicSpec, FrameSpec

FORM_ELEMENT = {"flatness": ("plane",), "straightness": ("line",), "roundness": ("circle",),
                "cylindricity": ("cylinder",)}
#: the residual derivative columns that are free zone parameters (small-angle form): the
#: locating offset / radius column is absorbed by the zone limits
FREE_COLUMNS = {"plane": (1, 2), "circle": (0, 1), "cylinder": (0, 1, 2, 3)}
STEP = 1e-5          # central-difference step, mm or rad
RAD = math.pi / 180.0


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
    #: the value of the task's points; ``value`` is the spec's ``measured`` value when it gives one
    points_value: float | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def u_unit(self) -> str:
        return "um" if self.unit == "mm" else "urad"


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


class Context:
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
            try:
                self._frames[name] = datum_frame(
                    self.geom(s.primary), self.geom(s.secondary) if s.secondary else None,
                    self.geom(s.tertiary) if s.tertiary else None)
            except ModelError as err:
                msg = str(err).removeprefix("datum frame: ")
                raise about(type(err)(msg), "frames", list(self.frame_specs).index(name),
                            f"datum frame {name}") from None
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


def form_residuals(ctx, c):
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


def form(ctx, c, consts, frozen):
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
        ctx = Context(ctx.jf, ctx.frame_specs, deltas={name: delta}, X=ctx.X, B=ctx.B)
    d, g = form_residuals(ctx, c)
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
        return form(ctx, c, consts, None)
    delta = np.zeros((1, f.n))
    basis, its = None, 0
    for _ in range(20):
        sub = Context(ctx.jf, ctx.frame_specs, deltas={name: delta}, X=ctx.X)
        d, g = form_residuals(sub, c)
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


VALUE = {"diameter": _size, "width": _size, "cone_angle": _size, "distance": _distance, "angle": _angle,
          "flatness": form, "straightness": form, "roundness": form, "cylindricity": form,
          "perpendicularity": _orientation, "parallelism": _orientation,
          "angularity": _orientation, "position": _position}


def constants(jf: JointFit, frames, c: CharacteristicSpec) -> dict:
    """What is fixed at the reference: an axis's length over its points, a position's heights."""
    ctx = Context(jf, frames)
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
    if c.type == "position" and (c.frame is None or c.nominal_position_mm is None):
        raise ModelError(f"characteristic {c.name}: position needs a datum frame and the nominal position")


# ------------------------------------------------------------------------------------------
# evaluation with sensitivities
# ------------------------------------------------------------------------------------------

def _point_columns(jf: JointFit, name: str, local: np.ndarray) -> np.ndarray:
    return np.asarray(jf.specs[name].indices, int)[local]


def _sensitivities(jf, frames, c, consts, frozen):
    """(s_A, s_Xd) by central differences with the active set held (module docstring), all
    perturbations in one batch."""
    fn = VALUE[c.type]
    n = jf.n
    deltas = {}
    for name, sl in jf.rows.items():
        d = np.zeros((2 * n, sl.stop - sl.start))
        j = np.arange(sl.start, sl.stop)
        d[j, j - sl.start] = STEP
        d[n + j, j - sl.start] = -STEP
        deltas[name] = d
    v, _ = fn(Context(jf, frames, deltas=deltas, B=2 * n), c, consts, frozen)
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
            v, _ = fn(Context(jf, frames, X=Xb, B=2 * k), c, consts, frozen)
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
    for k, fs in enumerate(frames.values()):
        for nm in (fs.primary, fs.secondary, fs.tertiary):
            if nm is not None and nm not in jf.fits:
                raise about(ModelError(f"datum frame {fs.name}: unknown feature {nm!r}"), "frames", k)
    order = sorted(range(len(chars)), key=lambda i: chars[i].type != "diameter")
    results: dict[int, Result] = {}
    by_name: dict[str, Result] = {}
    for i in order:
        try:
            res = _evaluate_one(jf, frames, chars[i], by_name)
        except ModelError as err:
            raise about(err, "characteristics", i, f"characteristic {chars[i].name}") from None
        results[i] = res
        by_name[chars[i].name] = res
    out = [results[i] for i in range(len(chars))]
    if V_X_um2 is not None:
        propagate(out, V_X_um2)
    return out


def _evaluate_one(jf: JointFit, frames: Mapping[str, FrameSpec], c: CharacteristicSpec,
                  by_name: dict[str, Result]) -> Result:
    """One characteristic's value and sensitivities (its size characteristic, for a bonus,
    already in ``by_name``)."""
    _check(c, jf, frames)
    consts = constants(jf, frames, c)
    ctx = Context(jf, frames)
    its = None
    if c.type in FORM_TYPES and c.method == "MZ":
        value, frozen = _mz_exact(ctx, c, consts)
        its = frozen.get("iterations")
    else:
        value, frozen = VALUE[c.type](ctx, c, consts, None)
    value = points_value = float(value[0])
    if c.measured is not None:      # measured elsewhere: these points give only the sensitivities (u)
        value = float(c.measured)
    s_A, s_Xd = _sensitivities(jf, frames, c, consts, frozen)
    s_X = s_Xd + s_A @ jf.G
    active = np.array([], int)
    if frozen is not None and "w" in frozen:
        active = _point_columns(jf, c.features[0], np.flatnonzero(frozen["w"]))
    res = Result(spec=c, value=value, unit="deg" if c.type in ("angle", "cone_angle") else "mm",
                 s_A=s_A,
                 s_X=s_X, smooth=c.type in SMOOTH_TYPES or (
                     c.type in ORIENTATION_TYPES and role(ctx.geom(c.features[0])) == AXIS),
                 active=active, zone_iterations=its, points_value=points_value)
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
    return res


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
