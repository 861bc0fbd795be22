"""The least-squares fit of an element (Forbes 2022 section 3): orthogonal distance regression by
Gauss-Newton in the stable parametrisation of the paper, from robust starting values, and the
sensitivity matrix G_A|X = G_A|D N^T, G_A|D = -(J^T W J)^{-1} J^T W at the solution
(eqs. (8), (12)); the method in the package docstring, :mod:`xlfuncs.features`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import ConvergenceError, DegenerateGeometryError, ModelError
from ..partial import frame_from_axis
from .models import CIRCLE_PLANES, ELEMENTS, GLOBAL_NAMES, K_RESIDUALS, LOCAL_NAMES, MIN_POINTS, local_model, update_one

# --------------------------------------------------------------------------------------------
# the fit
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FeatureFit:
    """A least-squares element fitted to points (Forbes 2022 section 3).

    ``origin_mm`` and ``R`` define the solution frame: local coordinates
    P = (X - origin) R, in which the element is in standard position.  ``shape`` holds r0
    (and phi).  J, the normals and the residuals are those of the solution (in machine
    coordinates for the normals).
    """

    element: str                  # line, plane, circle, sphere, cylinder, cone
    kind: str                     # element, or "circle_space"
    X_mm: np.ndarray              # m x 3
    weights: np.ndarray           # m
    origin_mm: np.ndarray         # 3
    R: np.ndarray                 # 3 x 3, columns = frame axes
    shape: tuple[float, ...]
    local_names: tuple[str, ...]
    local_values: np.ndarray
    names: tuple[str, ...]
    values: np.ndarray
    T: np.ndarray                 # global <- local, len(names) x len(local_names)
    J: np.ndarray                 # (k m) x n, rows ordered point by point
    normals: np.ndarray           # m x k x 3 (machine coordinates)
    residuals_mm: np.ndarray      # (k m)
    iterations: int
    circle_plane: str | None = None

    @property
    def m(self) -> int:
        return self.X_mm.shape[0]

    @property
    def n(self) -> int:
        return len(self.local_names)

    @property
    def k(self) -> int:
        return self.normals.shape[1]

    @property
    def P_local_mm(self) -> np.ndarray:
        return (self.X_mm - self.origin_mm) @ self.R

    @property
    def w2(self) -> np.ndarray:
        """Diagonal of W = diag(w_i^2) per residual row (eq. (12))."""
        return np.repeat(self.weights ** 2, self.k)

    @property
    def H(self) -> np.ndarray:
        """H = J^T W J."""
        return self.J.T @ (self.w2[:, None] * self.J)

    def G_A_D(self) -> np.ndarray:
        """G_A|D = -(J^T W J)^{-1} J^T W, n x (k m) (eqs. (8), (12))."""
        return -np.linalg.solve(self.H, self.J.T * self.w2[None, :])

    def gauss_newton_step(self) -> np.ndarray:
        """delta = -(J^T W J)^{-1} J^T W d from the fitted values, in the paper parameters
        (Forbes 2022 section 3: J^T W d = 0 at the solution, so delta = 0 up to rounding; the
        workbooks compute the same step on 'H' to show when edited points need a refit)."""
        return -np.linalg.solve(self.H, self.J.T @ (self.w2 * self.residuals_mm))

    def values_dict(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, self.values)}

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_mm ** 2)))


def G_A_X(f: FeatureFit) -> np.ndarray:
    """G_A|X = G_A|D N^T, n x 3m, columns interleaved x1, y1, z1, x2, ... (eq. (8)).

    Column block i is sum_r G_A|D[:, k i + r] n_{i,r}^T: moving x_i along the fitted normal
    n_{i,r} changes the residual by the same amount.
    """
    GD = f.G_A_D().reshape(f.n, f.m, f.k)
    return np.einsum("pir,irc->pic", GD, f.normals).reshape(f.n, 3 * f.m)


def _prepare(X, weights, element: str):
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ModelError("points must be an m x 3 array of coordinates in mm")
    if not np.all(np.isfinite(X)):
        raise ModelError("point coordinates must be finite numbers")
    m = X.shape[0]
    if weights is None:
        w = np.ones(m)
    else:
        w = np.asarray(weights, dtype=float).reshape(-1)
        if w.shape != (m,):
            raise ModelError(f"weights: need one weight per point ({m}), got {w.size}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ModelError("weights must be finite and non-negative")
    return X, w


def _algebraic_circle(P2: np.ndarray, w: np.ndarray, what: str):
    """Kasa fit x^2 + y^2 = 2 a x + 2 b y + c (weighted), for a starting estimate."""
    mu = np.average(P2, axis=0, weights=w)
    Q = P2 - mu
    A = np.column_stack([2 * Q, np.ones(len(Q))]) * w[:, None]
    rhs = (Q ** 2).sum(axis=1) * w
    sol, _, rank, sv = np.linalg.lstsq(A, rhs, rcond=None)
    if rank < 3 or sv[-1] <= 1e-10 * sv[0]:
        raise DegenerateGeometryError(f"{what}: the points are collinear, no circle through them")
    ctr = sol[:2]
    r2 = sol[2] + ctr @ ctr
    if not r2 > 0:
        raise DegenerateGeometryError(f"{what}: no circle through the points")
    return mu + ctr, math.sqrt(r2)


def _principal(X: np.ndarray, w: np.ndarray):
    mu = np.average(X, axis=0, weights=w)
    _, s, vt = np.linalg.svd((X - mu) * np.sqrt(w)[:, None], full_matrices=False)
    return mu, s, vt  # rows of vt: directions of decreasing spread


def _start_axis_elements(kind: str, X, w, N_points, axis_hint):
    """Candidate (origin, R, shape) starting estimates for cylinders and cones."""
    mu, _, vt = _principal(X, w)
    dirs = []
    if axis_hint is not None:
        dirs.append(np.asarray(axis_hint, float))
    if N_points is not None:
        Nn = np.asarray(N_points, float)
        if Nn.shape == X.shape and np.all(np.isfinite(Nn)):
            C = (Nn - np.average(Nn, axis=0, weights=w)) if kind == "cone" else Nn
            _, _, nvt = np.linalg.svd(C * np.sqrt(w)[:, None], full_matrices=False)
            dirs.append(nvt[-1])
    dirs += [vt[0], vt[2], vt[1]]
    starts = []
    for v in dirs:
        if not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
            continue
        R = frame_from_axis(v)
        P = (X - mu) @ R
        ctr = None
        if N_points is not None and kind == "cone":
            # the projected normals of a cone or cylinder point away from the axis:
            # least-squares intersection of the lines (p_i, n_i) in the plane orthogonal to v
            Nl = np.asarray(N_points, float) @ R
            n2 = Nl[:, :2]
            nn = np.linalg.norm(n2, axis=1)
            ok = nn > 1e-6
            if ok.sum() >= 2:
                n2 = n2[ok] / nn[ok, None]
                Pm = np.eye(2)[None] - n2[:, :, None] * n2[:, None, :]
                A = (Pm * w[ok, None, None]).sum(0)
                b = np.einsum("ijk,ik->j", Pm * w[ok, None, None], P[ok, :2])
                if np.linalg.cond(A) < 1e8:
                    ctr = np.linalg.solve(A, b)
        try:
            if ctr is None:
                ctr, _ = _algebraic_circle(P[:, :2], w, kind)
        except DegenerateGeometryError:
            continue
        origin = mu + R @ np.array([ctr[0], ctr[1], 0.0])
        Pl = (X - origin) @ R
        rho = np.hypot(Pl[:, 0], Pl[:, 1])
        if kind == "cylinder":
            starts.append((origin, R, (float(np.average(rho, weights=w)),)))
        else:
            A = np.column_stack([np.ones_like(rho), -Pl[:, 2]]) * np.sqrt(w)[:, None]
            sol, *_ = np.linalg.lstsq(A, rho * np.sqrt(w), rcond=None)
            r0, tp = float(sol[0]), float(sol[1])
            if r0 <= 0:
                continue
            starts.append((origin, R, (r0, math.atan(tp))))
    return starts


def _starts(kind, X, w, N_points, axis_hint, circle_plane):
    mu, _, vt = _principal(X, w)
    if kind == "line":
        v = vt[0] if axis_hint is None else np.asarray(axis_hint, float)
        return [(mu, frame_from_axis(v), ())]
    if kind == "plane":
        v = vt[2] if axis_hint is None else np.asarray(axis_hint, float)
        return [(mu, frame_from_axis(v), ())]
    if kind == "sphere":
        Q = X - mu
        A = np.column_stack([2 * Q, np.ones(len(Q))]) * w[:, None]
        rhs = (Q ** 2).sum(axis=1) * w
        sol, _, rank, sv = np.linalg.lstsq(A, rhs, rcond=None)
        if rank < 4 or sv[-1] <= 1e-10 * sv[0]:
            raise DegenerateGeometryError(
                "sphere fit: the points lie in one plane (or on a line), they do not "
                "determine a sphere")
        ctr = sol[:3]
        r2 = sol[3] + ctr @ ctr
        if not r2 > 0:
            raise DegenerateGeometryError("sphere fit: no sphere through the points")
        return [(mu + ctr, np.eye(3), (math.sqrt(r2),))]
    if kind == "circle":
        cols, _ = CIRCLE_PLANES[circle_plane]
        R = np.eye(3)[:, cols]
        P = X @ R
        ctr, r = _algebraic_circle(P[:, :2], w, "circle fit")
        return [(R @ np.array([ctr[0], ctr[1], 0.0]), R, (r,))]
    if kind == "circle_space":
        v = vt[2] if axis_hint is None else np.asarray(axis_hint, float)
        R = frame_from_axis(v)
        P = (X - mu) @ R
        ctr, r = _algebraic_circle(P[:, :2], w, "circle fit")
        return [(mu + R @ np.array([ctr[0], ctr[1], 0.0]), R, (r,))]
    return _start_axis_elements(kind, X, w, N_points, axis_hint)


def _gauss_newton(kind, X, w, origin, R, shape, scale, max_iter):
    k = K_RESIDUALS[kind]
    wr = np.repeat(w, k)  # residual rows are multiplied by w_i (eq. (11))

    def evaluate(o, Rm, sh):
        d, J, _ = local_model(kind, (X - o) @ Rm, sh)
        return d.reshape(-1) * wr, J.reshape(-1, J.shape[-1]) * wr[:, None]

    d, J = evaluate(origin, R, shape)
    ss = float(d @ d)
    mk = d.size
    for it in range(1, max_iter + 1):
        delta, *_ = np.linalg.lstsq(J, -d, rcond=None)
        step = float(np.linalg.norm(J @ delta))
        tol = 1e-12 * scale * math.sqrt(mk) + 1e-9 * math.sqrt(ss)
        if step <= tol:
            return origin, R, shape, it
        t = 1.0
        # the sum of squares a step may not increase beyond: its relative rounding, and what
        # rounding of the residuals (1e-13 x scale each, a tenth of the stopping rule's) changes
        # in it -- a step of 1e-9 mm lowers ss by ~1e-18 mm^2, far below the ~1e-17 mm^2 that
        # rounding moves ss when the residuals are 0.1 um, and was rejected 100 times over
        slack = ss * 1e-12 + (1e-3 * tol) ** 2 + 2.0 * math.sqrt(ss) * 1e-13 * scale * math.sqrt(mk)
        for _ in range(40):
            o2, R2, sh2 = update_one(kind, origin, R, shape, t * delta)
            try:
                d2, J2 = evaluate(o2, R2, sh2)
                ss2 = float(d2 @ d2)
            except DegenerateGeometryError:
                ss2 = math.inf
            if ss2 <= ss + slack:
                break
            t *= 0.5
        else:
            raise ConvergenceError(
                f"{_label(kind)} fit did not converge: no Gauss-Newton step reduces the sum of "
                f"squares at iteration {it} (rms residual {math.sqrt(ss / mk):.3g} mm)")
        origin, R, shape, d, J, ss = o2, R2, sh2, d2, J2, ss2
        if kind in ("circle", "circle_space", "sphere", "cylinder", "cone"):
            if abs(shape[0]) > 1e6 * scale:
                raise ConvergenceError(
                    f"{_label(kind)} fit did not converge: the radius grows without bound "
                    f"(r0 = {shape[0]:.3g} mm at iteration {it}); the points do not look like "
                    f"a {_label(kind)}")
        if kind == "cone" and math.cos(shape[1]) < 1e-8:
            raise ConvergenceError(
                "cone fit did not converge: the cone angle tends to 90 deg (a plane?)")
    raise ConvergenceError(
        f"{_label(kind)} fit did not converge in {max_iter} Gauss-Newton iterations "
        f"(last step changed the residuals by {step:.3g} mm)")


def _label(kind: str) -> str:
    return "circle (in space)" if kind == "circle_space" else kind


def _orient(kind, v, X, N_points, axis_hint):
    """Sign convention for the fitted direction: along axis_hint if given; a plane's normal
    along the mean of the points' outward normals if they agree; else the component of
    largest magnitude positive."""
    if axis_hint is not None:
        return v if float(v @ np.asarray(axis_hint, float)) >= 0 else -v
    if kind == "plane" and N_points is not None:
        mn = np.asarray(N_points, float).mean(axis=0)
        if abs(float(mn @ v)) > 0.5:
            return v if float(mn @ v) > 0 else -v
    i = int(np.argmax(np.abs(v)))
    return v if v[i] >= 0 else -v


def fit(element: str, X_mm, *, weights=None, normals=None, axis_hint=None,
        circle_plane: str | None = "xy", reference_mm=None, max_iter: int = 100) -> FeatureFit:
    """Least-squares orthogonal-distance fit of ``element`` to the points X_mm (m x 3).

    ``weights``: w_i >= 0 of eq. (11) (default 1).  ``normals``: the points' nominal outward
    normals (probing directions), used only for the starting estimate of cylinders and cones
    and the sign of a plane's normal.  ``axis_hint``: a rough axis/normal/line direction
    (starting estimate and sign of the reported direction).  ``circle_plane``: for
    ``element="circle"``, "xy", "yz" or "zx" for a circle in that coordinate plane (section 4;
    the third coordinate is ignored), or None for a circle in space.  ``reference_mm``: the
    locating point of a line, plane, cylinder or cone is the point of the axis (plane) nearest
    to this point (default: the weighted centroid of the points); a cone's r0 is its radius
    there.

    Raises ModelError for too few points, DegenerateGeometryError for a rank-deficient
    Jacobian (naming the parameter the points do not determine) and ConvergenceError when
    Gauss-Newton does not converge.
    """
    if element not in ELEMENTS:
        raise ModelError(f"unknown feature type {element!r}; known: {', '.join(ELEMENTS)}")
    kind = element
    if element == "circle":
        if circle_plane is None:
            kind = "circle_space"
        elif circle_plane not in CIRCLE_PLANES:
            raise ModelError(f"circle plane must be one of xy, yz, zx (or none for a circle in "
                             f"space), got {circle_plane!r}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1:
        raise ModelError("max_iter must be a positive integer")
    X, w = _prepare(X_mm, weights, element)
    m_eff = int(np.count_nonzero(w > 0))
    need = MIN_POINTS[kind]
    if m_eff < need:
        raise ModelError(f"a {_label(kind)} fit needs at least {need} points with positive "
                         f"weight, got {m_eff}")
    if axis_hint is not None:
        axis_hint = np.asarray(axis_hint, float)
        if axis_hint.shape != (3,) or not np.all(np.isfinite(axis_hint)) or \
                np.linalg.norm(axis_hint) == 0:
            raise ModelError("axis_hint must be three finite numbers, not all zero")
    if reference_mm is not None:
        reference_mm = np.asarray(reference_mm, float)
        if reference_mm.shape != (3,) or not np.all(np.isfinite(reference_mm)):
            raise ModelError("reference_mm must be three finite numbers")
    if normals is not None:
        normals = np.asarray(normals, float)
        if normals.shape != X.shape:
            raise ModelError("normals must have the same shape as the points")
    Xw = X[w > 0]
    ww = w[w > 0]
    scale = float(np.max(np.ptp(Xw, axis=0))) if Xw.shape[0] > 1 else 1.0
    if scale == 0.0:
        raise DegenerateGeometryError(f"{_label(kind)} fit: all points coincide")
    Nw = None if normals is None else normals[w > 0]

    starts = _starts(kind, Xw, ww, Nw, axis_hint, circle_plane)
    if not starts:
        raise DegenerateGeometryError(f"{_label(kind)} fit: no starting estimate; the points "
                                      f"do not look like a {_label(kind)}")
    best, first_err = None, None
    for origin, R, shape in starts:
        try:
            o, Rm, sh, its = _gauss_newton(kind, Xw, ww, origin, R, shape, scale, max_iter)
        except ModelError as err:
            first_err = first_err or err
            continue
        d, _, _ = local_model(kind, (Xw - o) @ Rm, sh)
        ss = float(((d * ww[:, None]) ** 2).sum())
        # A later start wins only by more than rounding: sums of squares within the noise floor
        # of the Gauss-Newton stopping rule (1e-12 * scale per residual) are equal fits, and the
        # first start is kept, so the choice does not depend on the CPU's BLAS kernel.
        noise = (1e-12 * scale) ** 2 * d.size
        if best is None or ss < best[0] * (1 - 1e-9) - noise:
            best = (ss, o, Rm, sh, its)
    if best is None:
        raise first_err
    _, o, Rm, sh, its = best
    return _finish(kind, element, X, w, o, Rm, sh, its, Nw, axis_hint, circle_plane,
                   reference_mm)


def _finish(kind, element, X, w, o, R, shape, its, N_points, axis_hint, circle_plane,
            reference_mm):
    """Canonical frame (locating point nearest to the reference point, smallest rotation to
    the oriented axis), Jacobian and normals at the solution, rank check."""
    mu = np.average(X, axis=0, weights=w) if reference_mm is None else reference_mm
    if kind in ("line", "plane", "circle_space", "cylinder", "cone"):
        v = R[:, 2]
        v2 = _orient(kind, v, X, N_points, axis_hint)
        if kind == "cone" and v2 @ v < 0:
            shape = (shape[0], -shape[1])
        v = v2
        if kind in ("line", "cylinder", "cone"):
            t = float((mu - o) @ v)
            o = o + t * v
            if kind == "cone":
                shape = (shape[0] - t * math.tan(shape[1]), shape[1])
        elif kind == "plane":
            o = mu - float((mu - o) @ v) * v
        R = frame_from_axis(v)
    P = (X - o) @ R
    d, J, Nl = local_model(kind, P, shape)
    m, k, n = J.shape
    Jf = J.reshape(m * k, n)
    normals = Nl @ R.T
    names_local = (tuple(("x0_mm", "y0_mm", "r0_mm")) if kind == "circle"
                   else LOCAL_NAMES[kind])
    _rank_check(kind, Jf * np.repeat(w, k)[:, None], names_local)

    # reported (global) parameters and T = d(global)/d(local)
    if kind == "sphere":
        names = GLOBAL_NAMES["sphere"]
        values = np.array([*o, shape[0]])
        T = np.eye(4)
        local_values = values.copy()
    elif kind == "circle":
        cols, cn = CIRCLE_PLANES[circle_plane]
        names = (cn[0], cn[1], "r0_mm")
        values = np.array([o[cols[0]], o[cols[1]], shape[0]])
        T = np.eye(3)
        local_values = values.copy()
    else:
        names = GLOBAL_NAMES[kind]
        v = R[:, 2]
        gvals = [*o, *v] + list(shape)
        values = np.array(gvals, dtype=float)
        nl = len(names_local)
        T = np.zeros((len(names), nl))
        ix = {nm: i for i, nm in enumerate(names_local)}
        for j, ax in enumerate(("x_A_mm", "y_A_mm", "z_A_mm")):
            if ax in ix:
                T[0:3, ix[ax]] = R[:, j]
        # direction: R (rot_y, -rot_x, 0)
        T[3:6, ix["rot_y_rad"]] = R[:, 0]
        T[3:6, ix["rot_x_rad"]] = -R[:, 1]
        for extra in ("r0_mm", "phi_rad"):
            if extra in ix:
                T[names.index(extra), ix[extra]] = 1.0
        local_values = np.zeros(nl)
        if "r0_mm" in ix:
            local_values[ix["r0_mm"]] = shape[0]
        if "phi_rad" in ix:
            local_values[ix["phi_rad"]] = shape[1]
    return FeatureFit(
        element=element, kind=kind, X_mm=X, weights=w, origin_mm=o, R=R, shape=tuple(shape),
        local_names=names_local, local_values=local_values, names=tuple(names), values=values,
        T=T, J=Jf, normals=normals, residuals_mm=d.reshape(-1), iterations=its,
        circle_plane=circle_plane if kind == "circle" else None)


def _rank_check(kind: str, Jw: np.ndarray, names: Sequence[str]) -> None:
    """Raise DegenerateGeometryError when the (column-scaled) Jacobian is rank-deficient,
    naming the parameter the points determine least."""
    cn = np.linalg.norm(Jw, axis=0)
    if np.any(cn == 0):
        j = int(np.argmin(cn))
        raise DegenerateGeometryError(
            f"{_label(kind)} fit: the points do not determine {names[j]} (rank-deficient "
            f"Jacobian; {_hint(kind)})")
    _, s, vt = np.linalg.svd(Jw / cn, full_matrices=False)
    if s[-1] <= 1e-9 * s[0]:
        j = int(np.argmax(np.abs(vt[-1])))
        raise DegenerateGeometryError(
            f"{_label(kind)} fit: the points do not determine {names[j]} (rank-deficient "
            f"Jacobian, singular-value ratio {s[-1] / s[0]:.1e}; {_hint(kind)})")


def _hint(kind: str) -> str:
    return {
        "plane": "are the points on one line?",
        "line": "do all points coincide?",
        "circle": "are the points collinear?",
        "circle_space": "are the points collinear?",
        "sphere": "are the points on one circle?",
        "cylinder": "are the points on one circle or one line of the cylinder?",
        "cone": "are the points on one circle or one generator of the cone?",
    }[kind]
