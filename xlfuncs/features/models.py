"""The elements of Forbes 2022 in standard position (axis along z, locating point at the origin):
their local and reported parameters, residuals, Jacobian and normals (sections 4-8), and the
frame and shape moved by a change of the local parameters (single and batched)."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..errors import DegenerateGeometryError, ModelError

ELEMENTS: tuple[str, ...] = ("line", "plane", "circle", "sphere", "cylinder", "cone")

#: smallest number of points (with positive weight) that can determine each element
MIN_POINTS = {"line": 2, "plane": 3, "circle": 3, "circle_space": 3, "sphere": 4,
              "cylinder": 5, "cone": 6}

CIRCLE_PLANES = {
    # plane: (frame R columns, names of the centre coordinates)
    "xy": ((0, 1, 2), ("x0_mm", "y0_mm")),
    "yz": ((1, 2, 0), ("y0_mm", "z0_mm")),
    "zx": ((2, 0, 1), ("z0_mm", "x0_mm")),
}

LOCAL_NAMES = {
    "line": ("x_A_mm", "y_A_mm", "rot_x_rad", "rot_y_rad"),
    "plane": ("z_A_mm", "rot_x_rad", "rot_y_rad"),
    "circle_space": ("x_A_mm", "y_A_mm", "z_A_mm", "rot_x_rad", "rot_y_rad", "r0_mm"),
    "sphere": ("x0_mm", "y0_mm", "z0_mm", "r0_mm"),
    "cylinder": ("x_A_mm", "y_A_mm", "rot_x_rad", "rot_y_rad", "r0_mm"),
    "cone": ("x_A_mm", "y_A_mm", "rot_x_rad", "rot_y_rad", "r0_mm", "phi_rad"),
}

GLOBAL_NAMES = {
    "line": ("x_A_mm", "y_A_mm", "z_A_mm", "dir_x", "dir_y", "dir_z"),
    "plane": ("x_A_mm", "y_A_mm", "z_A_mm", "n_x", "n_y", "n_z"),
    "circle_space": ("x0_mm", "y0_mm", "z0_mm", "n_x", "n_y", "n_z", "r0_mm"),
    "sphere": ("x0_mm", "y0_mm", "z0_mm", "r0_mm"),
    "cylinder": ("x_A_mm", "y_A_mm", "z_A_mm", "dir_x", "dir_y", "dir_z", "r0_mm"),
    "cone": ("x_A_mm", "y_A_mm", "z_A_mm", "dir_x", "dir_y", "dir_z", "r0_mm", "phi_rad"),
}

#: residuals per point
K_RESIDUALS = {"line": 2, "plane": 1, "circle": 1, "circle_space": 2, "sphere": 1,
               "cylinder": 1, "cone": 1}


# --------------------------------------------------------------------------------------------
# the local models: residuals, Jacobian and normals in standard position
# --------------------------------------------------------------------------------------------

def local_model(kind: str, P: np.ndarray, shape: Sequence[float]):
    """Residuals d (..., m, k), Jacobian J (..., m, k, n) with respect to the local parameters
    at zero, and unit normals (..., m, k, 3) in the frame, for points P (..., m, 3) given in
    the frame in which the element is in standard position.

    ``shape`` = (r0,) for circles, spheres and cylinders, (r0, phi) for cones, () otherwise.
    ``kind`` is an element name or ``"circle_space"``.  Leading batch dimensions are allowed
    (used by the vectorised Monte Carlo in the tests).
    """
    x, y, z = P[..., 0], P[..., 1], P[..., 2]
    zero = np.zeros_like(x)
    one = np.ones_like(x)
    if kind == "plane":
        d = z[..., None]
        J = np.stack([-one, -y, x], axis=-1)[..., None, :]
        Nl = np.stack([zero, zero, one], axis=-1)[..., None, :]
        return d, J, Nl
    if kind == "line":
        d = np.stack([x, y], axis=-1)
        J1 = np.stack([-one, zero, zero, -z], axis=-1)
        J2 = np.stack([zero, -one, z, zero], axis=-1)
        n1 = np.stack([one, zero, zero], axis=-1)
        n2 = np.stack([zero, one, zero], axis=-1)
        return d, np.stack([J1, J2], axis=-2), np.stack([n1, n2], axis=-2)
    if kind == "sphere":
        rho = np.sqrt(x * x + y * y + z * z)
        _nonzero(rho, "sphere", "a point coincides with the sphere centre")
        n = P / rho[..., None]
        d = (rho - shape[0])[..., None]
        J = -np.concatenate([n, one[..., None]], axis=-1)[..., None, :]
        return d, J, n[..., None, :]
    rho = np.sqrt(x * x + y * y)
    _nonzero(rho, kind, "a point lies on the axis")
    c, s = x / rho, y / rho
    if kind == "circle":
        d = (rho - shape[0])[..., None]
        J = np.stack([-c, -s, -one], axis=-1)[..., None, :]
        Nl = np.stack([c, s, zero], axis=-1)[..., None, :]
        return d, J, Nl
    if kind == "cylinder":
        d = (rho - shape[0])[..., None]
        J = np.stack([-c, -s, z * s, -z * c, -one], axis=-1)[..., None, :]
        Nl = np.stack([c, s, zero], axis=-1)[..., None, :]
        return d, J, Nl
    if kind == "circle_space":
        d = np.stack([z, rho - shape[0]], axis=-1)
        J1 = np.stack([zero, zero, -one, -y, x, zero], axis=-1)
        J2 = np.stack([-c, -s, zero, z * s, -z * c, -one], axis=-1)
        n1 = np.stack([zero, zero, one], axis=-1)
        n2 = np.stack([c, s, zero], axis=-1)
        return d, np.stack([J1, J2], axis=-2), np.stack([n1, n2], axis=-2)
    if kind == "cone":
        r0, phi = shape
        cp, sp = math.cos(phi), math.sin(phi)
        dC = rho - r0
        # Forbes 2022 eq. (26): d = cos(phi) d_C + sin(phi) d_P
        d = (cp * dC + sp * z)[..., None]
        J = np.stack([-cp * c, -cp * s, cp * z * s - sp * y, -cp * z * c + sp * x,
                      -cp * one, -sp * dC + cp * z], axis=-1)[..., None, :]
        Nl = np.stack([cp * c, cp * s, sp * one], axis=-1)[..., None, :]
        return d, J, Nl
    raise ModelError(f"unknown element {kind!r}")


def _nonzero(rho: np.ndarray, kind: str, what: str) -> None:
    if np.any(rho <= 0.0):
        raise DegenerateGeometryError(f"{kind} fit: {what}; the distance is not differentiable")


def _rot_xy(rx: float, ry: float) -> np.ndarray:
    """R_y(ry) R_x(rx): maps e_z to (sin ry cos rx, -sin rx, cos rx cos ry)."""
    cx, sx, cy, sy = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    return Ry @ Rx


def update_one(kind, origin, R, shape, delta):
    """Apply local parameter changes delta to the frame and shape."""
    if kind == "sphere":
        return origin + delta[:3], R, (shape[0] + delta[3],)
    if kind == "circle":
        return origin + R @ np.array([delta[0], delta[1], 0.0]), R, (shape[0] + delta[2],)
    if kind == "plane":
        dz, rx, ry = delta
        return origin + R[:, 2] * dz, R @ _rot_xy(rx, ry), ()
    if kind == "line":
        dx, dy, rx, ry = delta
        return origin + R @ np.array([dx, dy, 0.0]), R @ _rot_xy(rx, ry), ()
    if kind == "circle_space":
        dx, dy, dz, rx, ry, dr = delta
        return (origin + R @ np.array([dx, dy, dz]), R @ _rot_xy(rx, ry), (shape[0] + dr,))
    if kind == "cylinder":
        dx, dy, rx, ry, dr = delta
        return (origin + R @ np.array([dx, dy, 0.0]), R @ _rot_xy(rx, ry), (shape[0] + dr,))
    if kind == "cone":
        dx, dy, rx, ry, dr, dphi = delta
        return (origin + R @ np.array([dx, dy, 0.0]), R @ _rot_xy(rx, ry),
                (shape[0] + dr, shape[1] + dphi))
    raise ModelError(kind)


def rot_xy_batch(rx, ry) -> np.ndarray:
    """R_y(ry) R_x(rx) for arrays of angles (B,) -> (B, 3, 3), as :func:`_rot_xy`."""
    cx, sx, cy, sy = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry)
    z = np.zeros_like(rx)
    return np.stack([np.stack([cy, sy * sx, sy * cx], -1), np.stack([z, cx, -sx], -1),
                     np.stack([-sy, cy * sx, cy * cx], -1)], -2)


def update_frame(kind: str, origin, R, shape, delta):
    """The element moved by small changes of its local parameters (the paper's order,
    LOCAL_NAMES) -- the Gauss-Newton update of :func:`update_one` for a batch: ``delta`` (B x n),
    ``origin`` (3,), ``R`` (3 x 3), ``shape`` (s,) -> origin (B x 3), R (B x 3 x 3),
    shape (B x s).  Used by xlfuncs.characteristics to differentiate through the geometry."""
    d = np.asarray(delta, float)
    B = d.shape[0]
    o = np.broadcast_to(np.asarray(origin, float), (B, 3)).copy()
    Rb = np.broadcast_to(np.asarray(R, float), (B, 3, 3)).copy()
    sh = np.broadcast_to(np.asarray(shape, float), (B, len(shape))).copy()
    if kind == "sphere":
        return o + d[:, :3], Rb, sh + d[:, 3:4]
    if kind == "circle":
        return o + np.einsum("bij,bj->bi", Rb[:, :, :2], d[:, :2]), Rb, sh + d[:, 2:3]
    if kind == "plane":
        return o + Rb[:, :, 2] * d[:, :1], Rb @ rot_xy_batch(d[:, 1], d[:, 2]), sh
    if kind == "circle_space":
        return (o + np.einsum("bij,bj->bi", Rb, d[:, :3]), Rb @ rot_xy_batch(d[:, 3], d[:, 4]),
                sh + d[:, 5:6])
    if kind in ("line", "cylinder", "cone"):
        return (o + np.einsum("bij,bj->bi", Rb[:, :, :2], d[:, :2]),
                Rb @ rot_xy_batch(d[:, 2], d[:, 3]), sh + d[:, 4:])
    raise ModelError(kind)
