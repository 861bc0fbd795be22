"""Planning without data: analytic approximations for partial features (Forbes 2022, sections 4-9)
and the sampling strategies that build the nominal points of a feature task.

For points x_1..x_m spread approximately uniformly over a patch A of a geometric element, the
principle of Monte Carlo integration (Forbes 2022, eq. (15)) turns the sums in J^T J into
integrals over the patch:

    (1/m) J^T J  ~  H = (1/|A|) * integral_A  j(s)^T j(s) dA,        V = H^{-1},

so that for a point-cloud variance matrix V_X = sigma_R^2 I the fitted parameters have
V_A ~ (sigma_R^2 / m) V and u(a_j) = sigma_R * s(a_j) / sqrt(m) with s(a_j) = sqrt(V_jj).
:class:`Approximation` holds H, V and s for one patch; the tables of the paper list s.

Parameters are those of the local (paper) parametrisation used by :mod:`xlfuncs.features`, in
the frame of the element's nominal position (axis along z, locating point at the origin):

=========  ================================================================================
circle     x0_mm, y0_mm, r0_mm                                    (section 4, eq. (16))
circle     x_A_mm, y_A_mm, z_A_mm, rot_x_rad, rot_y_rad, r0_mm    (in space, 2 residuals)
sphere     x0_mm, y0_mm, z0_mm, r0_mm                             (section 5)
plane      z_A_mm, rot_x_rad, rot_y_rad                           (section 6, eq. (22))
cylinder   x_A_mm, y_A_mm, rot_x_rad, rot_y_rad, r0_mm            (section 7)
cone       x_A_mm, y_A_mm, rot_x_rad, rot_y_rad, r0_mm, phi_rad   (section 8)
line       x_A_mm, y_A_mm, rot_x_rad, rot_y_rad                   (line in space, 2 residuals)
=========  ================================================================================

rot_x and rot_y are small rotations of the axis about the frame's x and y axes: the axis
direction is R_y(rot_y) R_x(rot_x) e_z ~ (rot_y, -rot_x, 1).  These are the paper's u_A, v_A of
sections 7 and 8 (its Jacobian rows -[cos, sin, -z sin, z cos, 1]); see docs/errata.md.

Conventions found by reproducing the tables (docs/errata.md, "Forbes 2022"):

* sphere patch: H_A(2,4) = int sin(theta) int cos^2(phi), H_A(3,3) = (a2-a1) int sin^2(phi)
  cos(phi), H_A(3,4) = (a2-a1) int sin(phi) cos(phi) (misprinted or missing in section 5.1);
  H_gamma(1,1) has +cos^3(gamma)/3; V_alpha(4,4) of the segment is (alpha + sin(2 alpha)/2) /
  (3 alpha D14).
* cone patch (Tables 6, 7): uniform by area, i.e. weight rho(z) = r0 - z tan(phi) (signed: the
  phi = 70 deg row of Table 6 integrates past the apex), Table 6 with r0 = 100, a = 50,
  Table 7 with r0 = a = 50 and its rotation columns not multiplied by a.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial.legendre import leggauss

from .errors import DegenerateGeometryError, ModelError

__all__ = [
    "Approximation", "Sampling", "circle_arc", "sphere_patch", "sphere_cap", "sphere_band",
    "sphere_segment", "plane_rectangle", "cylinder_patch", "cone_patch", "line_segment",
    "sphere_full", "PATTERNS", "approximation", "sample", "frame_from_axis",
]


# --------------------------------------------------------------------------------------------
# the approximation object
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Approximation:
    """H = lim (1/m) J^T J for points spread uniformly over a patch (Forbes 2022, eq. (15)).

    ``V`` = H^{-1} and ``s`` = sqrt(diag V) are the quantities of Tables 1-8; for V_X =
    sigma_R^2 I, u(a) = sigma_R s / sqrt(m) (:meth:`u`).
    """

    element: str
    pattern: str
    parameter_names: tuple[str, ...]
    H: np.ndarray
    geometry: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        H = np.asarray(self.H, dtype=float)
        object.__setattr__(self, "H", 0.5 * (H + H.T))

    @property
    def V(self) -> np.ndarray:
        """V = H^{-1} (the paper's V_alpha, V_gamma, V_beta, V_a_alpha, ...)."""
        cond = np.linalg.cond(self.H)
        if not np.isfinite(cond) or cond > 1e15:
            raise DegenerateGeometryError(
                f"{self.pattern}: the patch does not determine all {self.element} parameters "
                f"(H is singular, condition number {cond:.3g})")
        V = np.linalg.inv(self.H)
        return 0.5 * (V + V.T)

    @property
    def s(self) -> np.ndarray:
        """s(a_j) = sqrt(V_jj): the entries of the paper's tables."""
        return np.sqrt(np.diag(self.V))

    def s_dict(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.parameter_names, self.s)}

    def u(self, sigma_R: float, m: int) -> np.ndarray:
        """u(a) = sigma_R s(a) / sqrt(m) (same unit as sigma_R for lengths; per unit of
        sigma_R/mm for the rotations and the cone angle)."""
        if m <= 0:
            raise ModelError(f"number of points must be positive, got {m}")
        return sigma_R * self.s / math.sqrt(m)


def _check_angle(name: str, value: float, lo: float, hi: float, *, lo_open=True) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ModelError(f"{name} must be a finite number, got {value!r}")
    if (v <= lo if lo_open else v < lo) or v > hi:
        raise ModelError(f"{name} must be in {'(' if lo_open else '['}{lo:g}, {hi:g}], got {v:g}")
    return v


def _check_positive(name: str, value: float) -> float:
    v = float(value)
    if not math.isfinite(v) or v <= 0:
        raise ModelError(f"{name} must be a positive number, got {value!r}")
    return v


# --------------------------------------------------------------------------------------------
# circle (section 4)
# --------------------------------------------------------------------------------------------

def _arc_means(alpha: float) -> tuple[float, float, float]:
    """Means of cos, cos^2, sin^2 over -alpha <= theta <= alpha (Appendix A)."""
    c = math.sin(alpha) / alpha
    c2 = 0.5 + math.sin(2 * alpha) / (4 * alpha)
    s2 = 0.5 - math.sin(2 * alpha) / (4 * alpha)
    return c, c2, s2


def circle_arc(alpha_rad: float, *, space: bool = False, r0_mm: float = 1.0) -> Approximation:
    """Arc -alpha <= theta <= alpha of a circle: H_alpha of Forbes 2022 eq. (16), Table 1.

    ``space=True``: circle in space (fitted plane + circle, two residuals per point); the
    out-of-plane parameters (z_A, rot_x, rot_y) then depend on the radius ``r0_mm``.
    """
    alpha = _check_angle("half arc angle alpha", alpha_rad, 0.0, math.pi)
    c, c2, s2 = _arc_means(alpha)
    if not space:
        H = np.array([[c2, 0.0, c], [0.0, s2, 0.0], [c, 0.0, 1.0]])
        return Approximation("circle", "circle_arc", ("x0_mm", "y0_mm", "r0_mm"), H,
                             {"alpha_rad": alpha})
    r = _check_positive("r0_mm", r0_mm)
    # rows of J: in-plane -[c, s, 0, 0, 0, 1]; out-of-plane [0, 0, -1, -r s, r c, 0]
    H = np.zeros((6, 6))
    H[np.ix_([0, 1, 5], [0, 1, 5])] = [[c2, 0.0, c], [0.0, s2, 0.0], [c, 0.0, 1.0]]
    H[np.ix_([2, 3, 4], [2, 3, 4])] = [[1.0, 0.0, -r * c], [0.0, r * r * s2, 0.0],
                                       [-r * c, 0.0, r * r * c2]]
    return Approximation("circle", "circle_arc",
                         ("x_A_mm", "y_A_mm", "z_A_mm", "rot_x_rad", "rot_y_rad", "r0_mm"), H,
                         {"alpha_rad": alpha, "r0_mm": r})


# --------------------------------------------------------------------------------------------
# sphere (section 5)
# --------------------------------------------------------------------------------------------

SPHERE_NAMES = ("x0_mm", "y0_mm", "z0_mm", "r0_mm")


def sphere_patch(theta1: float, theta2: float, phi1: float, phi2: float) -> Approximation:
    """Patch theta1 <= theta <= theta2 (azimuth), phi1 <= phi <= phi2 (elevation) of a sphere:
    H = H_A / |A| of Forbes 2022 section 5.1, with the corrected entries H_A(2,4), H_A(3,3) and
    the missing H_A(3,4) (docs/errata.md)."""
    if not (-math.pi - 1e-12 <= theta1 < theta2 <= math.pi + 1e-12):
        raise ModelError("sphere patch needs -180 <= theta1 < theta2 <= 180 deg")
    if not (-math.pi / 2 - 1e-12 <= phi1 < phi2 <= math.pi / 2 + 1e-12):
        raise ModelError("sphere patch needs -90 <= phi1 < phi2 <= 90 deg")

    def F(f, a, b):
        return f(b) - f(a)

    t1, t2, p1, p2 = theta1, theta2, phi1, phi2
    Ic2 = F(lambda t: t / 2 + math.sin(2 * t) / 4, t1, t2)
    Is2 = F(lambda t: t / 2 - math.sin(2 * t) / 4, t1, t2)
    Isc = F(lambda t: math.sin(t) ** 2 / 2, t1, t2)
    Ic = F(math.sin, t1, t2)
    Is = F(lambda t: -math.cos(t), t1, t2)
    I1 = t2 - t1
    c3 = F(lambda p: math.sin(p) - math.sin(p) ** 3 / 3, p1, p2)
    sc2 = F(lambda p: -math.cos(p) ** 3 / 3, p1, p2)
    c2 = F(lambda p: p / 2 + math.sin(2 * p) / 4, p1, p2)
    s2c = F(lambda p: math.sin(p) ** 3 / 3, p1, p2)
    sc = F(lambda p: math.sin(p) ** 2 / 2, p1, p2)
    c1 = F(math.sin, p1, p2)
    HA = np.array([
        [Ic2 * c3, Isc * c3, Ic * sc2, Ic * c2],
        [Isc * c3, Is2 * c3, Is * sc2, Is * c2],
        [Ic * sc2, Is * sc2, I1 * s2c, I1 * sc],
        [Ic * c2, Is * c2, I1 * sc, I1 * c1],
    ])
    area = I1 * c1
    return Approximation("sphere", "sphere_patch", SPHERE_NAMES, HA / area,
                         {"theta_rad": (t1, t2), "phi_rad": (p1, p2)})


def sphere_cap(gamma_rad: float) -> Approximation:
    """Cap pi/2 - gamma <= phi <= pi/2 (Table 2): H_gamma of section 5.2, with +cos^3/3 in
    H_gamma(1,1) (docs/errata.md)."""
    g = _check_angle("cap angle gamma", gamma_rad, 0.0, math.pi)
    cg = math.cos(g)
    h11 = (2.0 / 3.0 - cg + cg ** 3 / 3.0) / (2.0 * (1.0 - cg))
    h33 = (1.0 - cg ** 3) / 3.0 / (1.0 - cg)
    h34 = (1.0 - math.cos(2 * g)) / 4.0 / (1.0 - cg)
    H = np.array([[h11, 0, 0, 0], [0, h11, 0, 0], [0, 0, h33, h34], [0, 0, h34, 1.0]])
    return Approximation("sphere", "sphere_cap", SPHERE_NAMES, H, {"gamma_rad": g})


def sphere_full() -> Approximation:
    """Points uniformly over the whole sphere: H = diag(1/3, 1/3, 1/3, 1) (section 5)."""
    a = sphere_cap(math.pi)
    return Approximation("sphere", "sphere_full", SPHERE_NAMES, a.H, {})


def sphere_band(beta_rad: float) -> Approximation:
    """Equatorial band -beta <= phi <= beta (Table 3): V_beta of eq. (19)."""
    b = _check_angle("band half-angle beta", beta_rad, 0.0, math.pi / 2)
    sb2 = math.sin(b) ** 2
    H = np.diag([(1 - sb2 / 3) / 2, (1 - sb2 / 3) / 2, sb2 / 3, 1.0])
    return Approximation("sphere", "sphere_band", SPHERE_NAMES, H, {"beta_rad": b})


def sphere_segment(alpha_rad: float) -> Approximation:
    """Longitudinal segment -alpha <= theta <= alpha, pole to pole (Table 4): the inverse of
    V_alpha of eq. (20), H_alpha = [[(alpha + sin 2alpha/2)/(3 alpha), 0, 0, pi sin(alpha)/
    (4 alpha)], [0, (alpha - sin 2alpha/2)/(3 alpha), 0, 0], [0, 0, 1/3, 0], [., 0, 0, 1]]."""
    a = _check_angle("half segment angle alpha", alpha_rad, 0.0, math.pi)
    h11 = (a + math.sin(2 * a) / 2) / (3 * a)
    h22 = (a - math.sin(2 * a) / 2) / (3 * a)
    h14 = math.pi * math.sin(a) / (4 * a)
    H = np.array([[h11, 0, 0, h14], [0, h22, 0, 0], [0, 0, 1.0 / 3.0, 0], [h14, 0, 0, 1.0]])
    return Approximation("sphere", "sphere_segment", SPHERE_NAMES, H, {"alpha_rad": a})


# --------------------------------------------------------------------------------------------
# plane, line (section 6)
# --------------------------------------------------------------------------------------------

def plane_rectangle(a_mm: float, b_mm: float) -> Approximation:
    """Rectangle -a <= x <= a, -b <= y <= b of a plane: H_ab of eq. (22) in the order
    (z_A, rot_x, rot_y) = (z_A, -v_A, u_A): diag(1, b^2/3, a^2/3)."""
    a = _check_positive("half-width a_mm", a_mm)
    b = _check_positive("half-width b_mm", b_mm)
    H = np.diag([1.0, b * b / 3.0, a * a / 3.0])
    return Approximation("plane", "plane_rectangle", ("z_A_mm", "rot_x_rad", "rot_y_rad"), H,
                         {"a_mm": a, "b_mm": b})


def line_segment(a_mm: float) -> Approximation:
    """Segment -a <= z <= a of a line in space (two residuals per point): diag(1, 1, a^2/3,
    a^2/3) for (x_A, y_A, rot_x, rot_y)."""
    a = _check_positive("half-length a_mm", a_mm)
    H = np.diag([1.0, 1.0, a * a / 3.0, a * a / 3.0])
    return Approximation("line", "line_segment",
                         ("x_A_mm", "y_A_mm", "rot_x_rad", "rot_y_rad"), H, {"a_mm": a})


# --------------------------------------------------------------------------------------------
# cylinder (section 7), cone (section 8)
# --------------------------------------------------------------------------------------------

CYLINDER_NAMES = ("x_A_mm", "y_A_mm", "rot_x_rad", "rot_y_rad", "r0_mm")
CONE_NAMES = CYLINDER_NAMES + ("phi_rad",)


def cylinder_patch(alpha_rad: float, a_mm: float) -> Approximation:
    """Patch -alpha <= theta <= alpha, -a <= z <= a of a cylinder (Table 5): H_a_alpha of
    section 7 (Jacobian rows -[cos, sin, -z sin, z cos, 1])."""
    al = _check_angle("half arc angle alpha", alpha_rad, 0.0, math.pi)
    a = _check_positive("half-height a_mm", a_mm)
    c, c2, s2 = _arc_means(al)
    H = np.zeros((5, 5))
    H[0, 0], H[1, 1] = c2, s2
    H[0, 4] = H[4, 0] = c
    H[2, 2] = a * a / 3.0 * s2
    H[3, 3] = a * a / 3.0 * c2
    H[4, 4] = 1.0
    return Approximation("cylinder", "cylinder_patch", CYLINDER_NAMES, H,
                         {"alpha_rad": al, "a_mm": a})


def cone_jacobian_rows(theta, z, r0: float, phi: float) -> np.ndarray:
    """Jacobian rows of Forbes 2022 section 8 for points on the cone in standard position:
    [-cos(phi) cos(theta), -cos(phi) sin(theta), w sin(theta), -w cos(theta), -cos(phi),
    z / cos(phi)] with w = z / cos(phi) - r0 sin(phi)."""
    theta = np.asarray(theta, dtype=float)
    z = np.asarray(z, dtype=float)
    cp, sp = math.cos(phi), math.sin(phi)
    w = z / cp - r0 * sp
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([-cp * c, -cp * s, w * s, -w * c, np.full_like(c, -cp), z / cp], axis=-1)


def cone_z_moments(a_mm: float, r0_mm: float, phi_rad: float) -> tuple[float, float, float]:
    """Means of z, z^2, z^3 over -a <= z <= a with the area weight rho(z) = r0 - z tan(phi)."""
    a, r0, t = a_mm, r0_mm, math.tan(phi_rad)
    return -t * a * a / (3 * r0), a * a / 3, -t * a ** 4 / (5 * r0)


def cone_patch(alpha_rad: float, a_mm: float, r0_mm: float, phi_rad: float) -> Approximation:
    """Patch -alpha <= theta <= alpha, -a <= z <= a of the cone r = r0 - z tan(phi)
    (Tables 6, 7): H = (1/|A|) integral J^T J dA over the Jacobian rows of section 8
    (:func:`cone_jacobian_rows`), uniform by area, dA = rho(z) dtheta dz / cos(phi) with the
    signed rho = r0 - z tan(phi) (the paper's convention, docs/errata.md).

    The paper evaluates these integrals by quadrature; they have a closed form: the means over
    theta of cos, cos^2, sin^2 (Appendix A) times the rho-weighted means M1, M2 of z, z^2
    (:func:`cone_z_moments`); w = z/cos(phi) - r0 sin(phi) is linear in z.
    :func:`cone_patch_quadrature` checks it.
    """
    al = _check_angle("half arc angle alpha", alpha_rad, 0.0, math.pi)
    a = _check_positive("half-height a_mm", a_mm)
    r0 = _check_positive("r0_mm", r0_mm)
    phi = float(phi_rad)
    if not math.isfinite(phi) or abs(phi) >= math.pi / 2:
        raise ModelError(f"cone angle phi must be in (-90, 90) deg, got {math.degrees(phi):g}")
    c, c2, s2 = _arc_means(al)
    cp, sp = math.cos(phi), math.sin(phi)
    M1, M2, _ = cone_z_moments(a, r0, phi)
    Ew = M1 / cp - r0 * sp
    Ew2 = M2 / cp ** 2 - 2 * r0 * sp * M1 / cp + (r0 * sp) ** 2
    Ewz = M2 / cp - r0 * sp * M1
    H = np.zeros((6, 6))
    H[0, 0] = cp * cp * c2
    H[0, 3] = cp * c2 * Ew
    H[0, 4] = cp * cp * c
    H[0, 5] = -c * M1
    H[1, 1] = cp * cp * s2
    H[1, 2] = -cp * s2 * Ew
    H[2, 2] = s2 * Ew2
    H[3, 3] = c2 * Ew2
    H[3, 4] = cp * c * Ew
    H[3, 5] = -c * Ewz / cp
    H[4, 4] = cp * cp
    H[4, 5] = -M1
    H[5, 5] = M2 / (cp * cp)
    H = np.triu(H) + np.triu(H, 1).T
    return Approximation("cone", "cone_patch", CONE_NAMES, H,
                         {"alpha_rad": al, "a_mm": a, "r0_mm": r0, "phi_rad": phi})


def cone_patch_quadrature(alpha_rad: float, a_mm: float, r0_mm: float, phi_rad: float,
                          *, nodes: int = 48) -> Approximation:
    """:func:`cone_patch` by Gauss-Legendre quadrature of J^T J rho over (theta, z), as the
    paper describes ("one-dimensional quadrature routines")."""
    al, a, r0, phi = float(alpha_rad), float(a_mm), float(r0_mm), float(phi_rad)
    x, w = leggauss(nodes)
    T, Z = np.meshgrid(al * x, a * x, indexing="ij")
    W = np.outer(al * w, a * w) * (r0 - math.tan(phi) * Z)
    J = cone_jacobian_rows(T, Z, r0, phi)
    H = np.einsum("ij,ijk,ijl->kl", W, J, J) / W.sum()
    return Approximation("cone", "cone_patch", CONE_NAMES, H,
                         {"alpha_rad": al, "a_mm": a, "r0_mm": r0, "phi_rad": phi})


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
        a = _check_positive("half_length_mm", g["half_length_mm"])
        n = _count("n_points", g["n_points"], 2)
        z = _midpoints(-a, a, n)
        P = np.column_stack([np.zeros(n), np.zeros(n), z])
        Nl = np.tile([1.0, 0.0, 0.0], (n, 1))  # probing direction: frame x
        approx = line_segment(a)
    elif pattern == "plane_rectangle":
        a = _check_positive("half_width_x_mm", g["half_width_x_mm"])
        b = _check_positive("half_width_y_mm", g["half_width_y_mm"])
        nx, ny = _count("n_x", g["n_x"]), _count("n_y", g["n_y"])
        X, Y = np.meshgrid(_midpoints(-a, a, nx), _midpoints(-b, b, ny), indexing="ij")
        P = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
        Nl = np.tile([0.0, 0.0, 1.0], (X.size, 1))
        approx = plane_rectangle(a, b)
    elif pattern == "circle_arc":
        r = _check_positive("r0_mm", g["r0_mm"])
        al = _check_angle("arc_deg", g["arc_deg"], 0.0, 360.0) / 2
        n = _count("n_points", g["n_points"], 3)
        t = _midpoints(-rad(al), rad(al), n)
        P = np.column_stack([r * np.cos(t), r * np.sin(t), np.zeros(n)])
        Nl = np.column_stack([np.cos(t), np.sin(t), np.zeros(n)])
        approx = circle_arc(rad(al), space=bool(g.get("space", False)), r0_mm=r)
    elif pattern.startswith("sphere_"):
        r = _check_positive("r0_mm", g["r0_mm"])
        if pattern == "sphere_rings":
            el = [float(e) for e in np.atleast_1d(g["elevations_deg"])]
            counts = [_count("points_per_ring", c) for c in np.atleast_1d(g["points_per_ring"])]
            if len(el) != len(counts):
                raise ModelError("elevations_deg and points_per_ring must have the same length")
            ts, ps = [], []
            for e, c in zip(el, counts):
                _check_angle("elevations_deg", e, -90.0, 90.0, lo_open=False)
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
                gm = rad(_check_angle("gamma_deg", g["gamma_deg"], 0.0, 180.0))
                t1, t2, p1, p2 = -math.pi, math.pi, math.pi / 2 - gm, math.pi / 2
                approx = sphere_cap(gm)
            elif pattern == "sphere_band":
                be = rad(_check_angle("beta_deg", g["beta_deg"], 0.0, 90.0))
                t1, t2, p1, p2 = -math.pi, math.pi, -be, be
                approx = sphere_band(be)
            elif pattern == "sphere_segment":
                al = rad(_check_angle("arc_deg", g["arc_deg"], 0.0, 360.0)) / 2
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
        r = _check_positive("r0_mm", g["r0_mm"])
        al = rad(_check_angle("arc_deg", g["arc_deg"], 0.0, 360.0)) / 2
        a = _check_positive("half_height_mm", g["half_height_mm"])
        nt, nz = _count("n_theta", g["n_theta"]), _count("n_z", g["n_z"])
        T, Z = np.meshgrid(_midpoints(-al, al, nt), _midpoints(-a, a, nz), indexing="ij")
        t, z = T.ravel(), Z.ravel()
        Nl = np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
        P = np.column_stack([r * np.cos(t), r * np.sin(t), z])
        approx = cylinder_patch(al, a)
    else:  # cone_patch
        r = _check_positive("r0_mm", g["r0_mm"])
        phi = rad(float(g["phi_deg"]))
        if not abs(phi) < math.pi / 2:
            raise ModelError("phi_deg must be in (-90, 90)")
        al = rad(_check_angle("arc_deg", g["arc_deg"], 0.0, 360.0)) / 2
        a = _check_positive("half_height_mm", g["half_height_mm"])
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
