"""Planning without data: analytic approximations for partial features (Forbes 2022, sections 4-9).
The sampling strategies that build the nominal points of a feature task are
:mod:`xlfuncs.partial.sampling`.

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

from ..errors import DegenerateGeometryError, ModelError

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


def check_angle(name: str, value: float, lo: float, hi: float, *, lo_open=True) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ModelError(f"{name} must be a finite number, got {value!r}")
    if (v <= lo if lo_open else v < lo) or v > hi:
        raise ModelError(f"{name} must be in {'(' if lo_open else '['}{lo:g}, {hi:g}], got {v:g}")
    return v


def check_positive(name: str, value: float) -> float:
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
    alpha = check_angle("half arc angle alpha", alpha_rad, 0.0, math.pi)
    c, c2, s2 = _arc_means(alpha)
    if not space:
        H = np.array([[c2, 0.0, c], [0.0, s2, 0.0], [c, 0.0, 1.0]])
        return Approximation("circle", "circle_arc", ("x0_mm", "y0_mm", "r0_mm"), H,
                             {"alpha_rad": alpha})
    r = check_positive("r0_mm", r0_mm)
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
    g = check_angle("cap angle gamma", gamma_rad, 0.0, math.pi)
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
    b = check_angle("band half-angle beta", beta_rad, 0.0, math.pi / 2)
    sb2 = math.sin(b) ** 2
    H = np.diag([(1 - sb2 / 3) / 2, (1 - sb2 / 3) / 2, sb2 / 3, 1.0])
    return Approximation("sphere", "sphere_band", SPHERE_NAMES, H, {"beta_rad": b})


def sphere_segment(alpha_rad: float) -> Approximation:
    """Longitudinal segment -alpha <= theta <= alpha, pole to pole (Table 4): the inverse of
    V_alpha of eq. (20), H_alpha = [[(alpha + sin 2alpha/2)/(3 alpha), 0, 0, pi sin(alpha)/
    (4 alpha)], [0, (alpha - sin 2alpha/2)/(3 alpha), 0, 0], [0, 0, 1/3, 0], [., 0, 0, 1]]."""
    a = check_angle("half segment angle alpha", alpha_rad, 0.0, math.pi)
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
    a = check_positive("half-width a_mm", a_mm)
    b = check_positive("half-width b_mm", b_mm)
    H = np.diag([1.0, b * b / 3.0, a * a / 3.0])
    return Approximation("plane", "plane_rectangle", ("z_A_mm", "rot_x_rad", "rot_y_rad"), H,
                         {"a_mm": a, "b_mm": b})


def line_segment(a_mm: float) -> Approximation:
    """Segment -a <= z <= a of a line in space (two residuals per point): diag(1, 1, a^2/3,
    a^2/3) for (x_A, y_A, rot_x, rot_y)."""
    a = check_positive("half-length a_mm", a_mm)
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
    al = check_angle("half arc angle alpha", alpha_rad, 0.0, math.pi)
    a = check_positive("half-height a_mm", a_mm)
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
    al = check_angle("half arc angle alpha", alpha_rad, 0.0, math.pi)
    a = check_positive("half-height a_mm", a_mm)
    r0 = check_positive("r0_mm", r0_mm)
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
