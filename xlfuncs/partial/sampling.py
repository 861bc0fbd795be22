"""Sampling strategies of a feature task (Forbes 2022, sections 4-9): the nominal frame of an
element from its axis, and the nominal points and normals of each pattern of
:data:`PATTERNS`, spread uniformly over the patch, with the analytic approximation
(:mod:`xlfuncs.partial.approximations`) of the same patch."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import DegenerateGeometryError, ModelError
from .approximations import (
    Approximation,
    check_angle,
    check_positive,
    circle_arc,
    cone_patch,
    cylinder_patch,
    line_segment,
    plane_rectangle,
    sphere_band,
    sphere_cap,
    sphere_full,
    sphere_patch,
    sphere_segment,
)

# --------------------------------------------------------------------------------------------
# nominal frames and sampling strategies
# --------------------------------------------------------------------------------------------

def _unit(v, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ModelError(f"{name} must be three finite numbers")
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise DegenerateGeometryError(f"{name} must not be the zero vector")
    return v / n


def frame_from_axis(axis, ref_dir=None) -> np.ndarray:
    """A right-handed rotation R (columns = frame x, y, z axes in machine coordinates) with
    R e_z = axis.  Without ``ref_dir`` R is the smallest rotation taking e_z to the axis (the
    identity for axis = e_z); with ``ref_dir`` the frame x axis is ref_dir projected orthogonal
    to the axis (theta = 0 of the sampling patterns)."""
    v = _unit(axis, "axis")
    if ref_dir is None:
        c = v[2]
        s2 = v[0] * v[0] + v[1] * v[1]
        if s2 > 0.0:
            k = np.array([-v[1], v[0], 0.0])  # e_z x v
            K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            # Rodrigues: R = I + K + K^2 / (1 + c).  For an axis near -e_z, 1 + c cancels (a
            # plane's normal 1e-5 rad from -z has 1 + c = 7e-11 with a relative error of 1e-6,
            # enough to tilt R e_z by 4e-11 rad, differently on every BLAS kernel); there the
            # identity 1 + c = (v_x^2 + v_y^2) / (1 - c) of a unit vector is exact to rounding
            inv = 1.0 / (1.0 + c) if c >= 0.0 else (1.0 - c) / s2
            R = np.eye(3) + K + (K @ K) * inv
        else:
            R = np.eye(3) if c > 0.0 else np.diag([1.0, -1.0, -1.0])  # rotation by pi about x
        # re-orthonormalise against rounding
        u, _, vt = np.linalg.svd(R)
        return u @ vt
    e = _unit(ref_dir, "ref_dir")
    e = e - (e @ v) * v
    ne = float(np.linalg.norm(e))
    if ne < 1e-9:
        raise DegenerateGeometryError("ref_dir must not be parallel to the axis")
    e = e / ne
    return np.column_stack([e, np.cross(v, e), v])


@dataclass(frozen=True)
class Sampling:
    """Nominal points (mm) and outward unit normals of a sampling strategy, plus the analytic
    approximation of the same patch (``approximation``; None for ``sphere_rings``)."""

    pattern: str
    element: str
    X_mm: np.ndarray
    N: np.ndarray
    approximation: Approximation | None
    labels: tuple[str, ...] = ()

    @property
    def m(self) -> int:
        return self.X_mm.shape[0]


def _midpoints(lo: float, hi: float, n: int) -> np.ndarray:
    return lo + (np.arange(n) + 0.5) * (hi - lo) / n


def _count(name: str, n, minimum: int = 1) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < minimum:
        raise ModelError(f"{name} must be an integer >= {minimum}, got {n!r}")
    return int(n)


def _place(P: np.ndarray, Nl: np.ndarray, center, R: np.ndarray):
    c = np.asarray(center, dtype=float).reshape(3)
    if not np.all(np.isfinite(c)):
        raise ModelError("center_mm must be three finite numbers")
    return P @ R.T + c, Nl @ R.T


#: sampling patterns, their element, required and optional keys (task keys of [sampling])
PATTERNS: dict[str, dict] = {
    "line_segment": {"element": "line", "keys": ("half_length_mm", "n_points")},
    "plane_rectangle": {"element": "plane",
                        "keys": ("half_width_x_mm", "half_width_y_mm", "n_x", "n_y")},
    "circle_arc": {"element": "circle", "keys": ("r0_mm", "arc_deg", "n_points")},
    "sphere_cap": {"element": "sphere", "keys": ("r0_mm", "gamma_deg", "n_theta", "n_phi")},
    "sphere_band": {"element": "sphere", "keys": ("r0_mm", "beta_deg", "n_theta", "n_phi")},
    "sphere_segment": {"element": "sphere", "keys": ("r0_mm", "arc_deg", "n_theta", "n_phi")},
    "sphere_patch": {"element": "sphere",
                     "keys": ("r0_mm", "theta_deg", "phi_range_deg", "n_theta", "n_phi")},
    "sphere_rings": {"element": "sphere", "keys": ("r0_mm", "elevations_deg", "points_per_ring")},
    "cylinder_patch": {"element": "cylinder",
                       "keys": ("r0_mm", "arc_deg", "half_height_mm", "n_theta", "n_z")},
    "cone_patch": {"element": "cone",
                   "keys": ("r0_mm", "phi_deg", "arc_deg", "half_height_mm", "n_theta", "n_z")},
}

COMMON_SAMPLING_KEYS = ("pattern", "center_mm", "axis", "ref_dir", "probe", "space",
                        "north_pole", "south_pole")


def approximation(pattern: str, **g) -> Approximation:
    """The analytic approximation for a sampling pattern, from the same keys as :func:`sample`
    (angles in degrees as in the task files; counts are not needed)."""
    rad = math.radians
    if pattern == "line_segment":
        return line_segment(g["half_length_mm"])
    if pattern == "plane_rectangle":
        return plane_rectangle(g["half_width_x_mm"], g["half_width_y_mm"])
    if pattern == "circle_arc":
        return circle_arc(rad(g["arc_deg"]) / 2, space=bool(g.get("space", False)),
                          r0_mm=g.get("r0_mm", 1.0))
    if pattern == "sphere_cap":
        return sphere_cap(rad(g["gamma_deg"]))
    if pattern == "sphere_band":
        return sphere_band(rad(g["beta_deg"]))
    if pattern == "sphere_segment":
        return sphere_segment(rad(g["arc_deg"]) / 2)
    if pattern == "sphere_patch":
        t1, t2 = (rad(v) for v in _pair("theta_deg", g["theta_deg"]))
        p1, p2 = (rad(v) for v in _pair("phi_range_deg", g["phi_range_deg"]))
        return sphere_patch(t1, t2, p1, p2)
    if pattern == "sphere_full":
        return sphere_full()
    if pattern == "cylinder_patch":
        return cylinder_patch(rad(g["arc_deg"]) / 2, g["half_height_mm"])
    if pattern == "cone_patch":
        return cone_patch(rad(g["arc_deg"]) / 2, g["half_height_mm"], g["r0_mm"],
                          rad(g["phi_deg"]))
    raise ModelError(f"no analytic approximation for pattern {pattern!r}")


def _pair(name: str, v) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in v)
    except (TypeError, ValueError):
        raise ModelError(f"{name} must be a pair of numbers [from, to]") from None
    if not (math.isfinite(a) and math.isfinite(b)) or not a < b:
        raise ModelError(f"{name} must be two finite numbers with from < to")
    return a, b


def sample(pattern: str, *, center_mm=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), ref_dir=None,
           **g) -> Sampling:
    """Nominal points and outward normals of a measurement strategy on a patch.

    Points are spread as a midpoint grid, uniform by area, so that (1/m) J^T J approaches the
    :class:`Approximation` of the same patch as the counts grow (Forbes 2022 eq. (15)).
    ``axis`` is the element axis (plane normal, circle/cylinder/cone axis, sphere polar axis,
    line direction) and ``ref_dir`` the direction of theta = 0 (default: the frame x axis of
    :func:`frame_from_axis`).
    """
    if pattern not in PATTERNS:
        raise ModelError(f"unknown sampling pattern {pattern!r}; known: {', '.join(PATTERNS)}")
    spec = PATTERNS[pattern]
    for k in spec["keys"]:
        if k not in g:
            raise ModelError(f"sampling pattern {pattern!r} needs {k}")
    R = frame_from_axis(axis, ref_dir)
    rad = math.radians
    element = spec["element"]
    approx: Approximation | None = None

    if pattern == "line_segment":
        a = check_positive("half_length_mm", g["half_length_mm"])
        n = _count("n_points", g["n_points"], 2)
        z = _midpoints(-a, a, n)
        P = np.column_stack([np.zeros(n), np.zeros(n), z])
        Nl = np.tile([1.0, 0.0, 0.0], (n, 1))  # probing direction: frame x
        approx = line_segment(a)
    elif pattern == "plane_rectangle":
        a = check_positive("half_width_x_mm", g["half_width_x_mm"])
        b = check_positive("half_width_y_mm", g["half_width_y_mm"])
        nx, ny = _count("n_x", g["n_x"]), _count("n_y", g["n_y"])
        X, Y = np.meshgrid(_midpoints(-a, a, nx), _midpoints(-b, b, ny), indexing="ij")
        P = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
        Nl = np.tile([0.0, 0.0, 1.0], (X.size, 1))
        approx = plane_rectangle(a, b)
    elif pattern == "circle_arc":
        r = check_positive("r0_mm", g["r0_mm"])
        al = check_angle("arc_deg", g["arc_deg"], 0.0, 360.0) / 2
        n = _count("n_points", g["n_points"], 3)
        t = _midpoints(-rad(al), rad(al), n)
        P = np.column_stack([r * np.cos(t), r * np.sin(t), np.zeros(n)])
        Nl = np.column_stack([np.cos(t), np.sin(t), np.zeros(n)])
        approx = circle_arc(rad(al), space=bool(g.get("space", False)), r0_mm=r)
    elif pattern.startswith("sphere_"):
        r = check_positive("r0_mm", g["r0_mm"])
        if pattern == "sphere_rings":
            el = [float(e) for e in np.atleast_1d(g["elevations_deg"])]
            counts = [_count("points_per_ring", c) for c in np.atleast_1d(g["points_per_ring"])]
            if len(el) != len(counts):
                raise ModelError("elevations_deg and points_per_ring must have the same length")
            ts, ps = [], []
            for e, c in zip(el, counts):
                check_angle("elevations_deg", e, -90.0, 90.0, lo_open=False)
                ts += list(2 * math.pi * np.arange(c) / c)
                ps += [rad(e)] * c
            if g.get("north_pole", False):
                ts.append(0.0)
                ps.append(math.pi / 2)
            if g.get("south_pole", False):
                ts.append(0.0)
                ps.append(-math.pi / 2)
            t, p = np.array(ts), np.array(ps)
        else:
            nt, npf = _count("n_theta", g["n_theta"]), _count("n_phi", g["n_phi"])
            if pattern == "sphere_cap":
                gm = rad(check_angle("gamma_deg", g["gamma_deg"], 0.0, 180.0))
                t1, t2, p1, p2 = -math.pi, math.pi, math.pi / 2 - gm, math.pi / 2
                approx = sphere_cap(gm)
            elif pattern == "sphere_band":
                be = rad(check_angle("beta_deg", g["beta_deg"], 0.0, 90.0))
                t1, t2, p1, p2 = -math.pi, math.pi, -be, be
                approx = sphere_band(be)
            elif pattern == "sphere_segment":
                al = rad(check_angle("arc_deg", g["arc_deg"], 0.0, 360.0)) / 2
                t1, t2, p1, p2 = -al, al, -math.pi / 2, math.pi / 2
                approx = sphere_segment(al)
            else:
                t1, t2 = (rad(v) for v in _pair("theta_deg", g["theta_deg"]))
                p1, p2 = (rad(v) for v in _pair("phi_range_deg", g["phi_range_deg"]))
                approx = sphere_patch(t1, t2, p1, p2)
            # uniform by area: midpoints in theta and in sin(phi) (Archimedes)
            T, S = np.meshgrid(_midpoints(t1, t2, nt),
                               _midpoints(math.sin(p1), math.sin(p2), npf), indexing="ij")
            t, p = T.ravel(), np.arcsin(np.clip(S.ravel(), -1.0, 1.0))
        Nl = np.column_stack([np.cos(t) * np.cos(p), np.sin(t) * np.cos(p), np.sin(p)])
        P = r * Nl
    elif pattern == "cylinder_patch":
        r = check_positive("r0_mm", g["r0_mm"])
        al = rad(check_angle("arc_deg", g["arc_deg"], 0.0, 360.0)) / 2
        a = check_positive("half_height_mm", g["half_height_mm"])
        nt, nz = _count("n_theta", g["n_theta"]), _count("n_z", g["n_z"])
        T, Z = np.meshgrid(_midpoints(-al, al, nt), _midpoints(-a, a, nz), indexing="ij")
        t, z = T.ravel(), Z.ravel()
        Nl = np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
        P = np.column_stack([r * np.cos(t), r * np.sin(t), z])
        approx = cylinder_patch(al, a)
    else:  # cone_patch
        r = check_positive("r0_mm", g["r0_mm"])
        phi = rad(float(g["phi_deg"]))
        if not abs(phi) < math.pi / 2:
            raise ModelError("phi_deg must be in (-90, 90)")
        al = rad(check_angle("arc_deg", g["arc_deg"], 0.0, 360.0)) / 2
        a = check_positive("half_height_mm", g["half_height_mm"])
        nt, nz = _count("n_theta", g["n_theta"]), _count("n_z", g["n_z"])
        tp = math.tan(phi)
        if r - abs(tp) * a <= 0:
            raise DegenerateGeometryError(
                "cone_patch: the band -half_height_mm <= z <= half_height_mm reaches the apex "
                f"(r0_mm - |tan(phi)| * half_height_mm = {r - abs(tp) * a:g} mm)")
        # uniform by area: equal-area bands (area ~ integral of r0 - z tan(phi) dz)
        q = _midpoints(0.0, 1.0, nz)
        total = 2 * a * r
        target = q * total  # F(z) = r (z + a) - tp (z^2 - a^2)/2
        if abs(tp) < 1e-15:
            zl = -a + target / r
        else:
            # -tp/2 z^2 + r z + (r a + tp a^2/2 - target) = 0, root inside [-a, a]
            A, B, C = -tp / 2, r, r * a + tp * a * a / 2 - target
            disc = np.sqrt(B * B - 4 * A * C)
            zl = (-B + disc) / (2 * A)
            bad = (zl < -a - 1e-9) | (zl > a + 1e-9)
            zl = np.where(bad, (-B - disc) / (2 * A), zl)
        T, Z = np.meshgrid(_midpoints(-al, al, nt), zl, indexing="ij")
        t, z = T.ravel(), Z.ravel()
        rho = r - tp * z
        P = np.column_stack([rho * np.cos(t), rho * np.sin(t), z])
        Nl = np.column_stack([math.cos(phi) * np.cos(t), math.cos(phi) * np.sin(t),
                              np.full_like(t, math.sin(phi))])
        approx = cone_patch(al, a, r, phi)

    X, N = _place(P, Nl, center_mm, R)
    labels = tuple(f"X{i + 1}" for i in range(X.shape[0]))
    return Sampling(pattern, element, X, N, approx, labels)
