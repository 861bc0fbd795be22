"""Datum reference frames from fitted datum features (ASME Y14.5-2018 ch. 4, ISO 5459:2011).

The fitted features are least-squares (Forbes 2022) associated features; the standards' datum
is the constrained extremal (tangent) feature -- the least-squares association is the usual CMM
convention and is what is propagated here (docs/characteristics.md).

A frame is built with the standard precedence:

* primary: a plane.  Its normal fixes the frame's z axis, pointing into the material (the fitted
  datum plane's normal is oriented along the points' outward normals, so z = -n_A), and the plane
  fixes the origin along z.
* secondary: a plane, orientation constrained by the primary: x = -(n_B projected orthogonal to
  z), pointing into the material, and the plane fixes the origin along its normal; or an axis
  (cylinder, line, circle in space) or a point (circle in a coordinate plane, sphere): the
  origin is where the axis meets the primary plane (a point: its projection along z).
* tertiary after a secondary plane: a plane fixes the last translation (origin = the
  intersection of the three planes); an axis or point fixes it by its location along y.  After a
  secondary axis/point the tertiary clocks the rotation about z: x points from the origin
  towards the tertiary feature's location, projected orthogonal to z.

y = z x x makes the frame right-handed.  Everything is batched: arrays carry a leading dimension
B (draws of a Monte Carlo, or the perturbations of a central difference).  Datum features of
size at MMC/LMC (datum shift, ASME Y14.5 4.11.4) are not supported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import DegenerateGeometryError, ModelError
from .partial import frame_from_axis

__all__ = ["Geometry", "Frame", "datum_frame", "PLANE", "AXIS", "POINT", "role"]

PLANE, AXIS, POINT = "plane", "axis", "point"
#: the smallest angle between datums that still fixes a frame: a secondary plane or axis within
#: this angle of parallel to the primary plane, or a tertiary plane within it of the line of the
#: other two, leaves a direction or the origin undetermined (a 0.1 mrad tilt between nominally
#: parallel planes put the origin kilometres away); refused instead of computed
MIN_DATUM_ANGLE_DEG = 1.0
_MIN_SIN = float(np.sin(np.radians(MIN_DATUM_ANGLE_DEG)))


@dataclass(frozen=True)
class Geometry:
    """A fitted element as geometry, batched: ``point`` (B x 3, locating point / centre, mm),
    ``R`` (B x 3 x 3, the element's frame, column 2 its axis or normal), ``shape`` (B x s: r0
    [, phi]) and ``element``/``kind`` as in :class:`xlfuncs.features.FeatureFit`."""

    element: str
    kind: str
    point: np.ndarray
    R: np.ndarray
    shape: np.ndarray

    @property
    def direction(self) -> np.ndarray | None:
        """Unit axis / normal (B x 3); None for a sphere."""
        return None if self.kind == "sphere" else self.R[:, :, 2]


def role(g: Geometry) -> str:
    """plane, axis (line, cylinder, cone, circle in space) or point (sphere, circle in a
    coordinate plane -- its centre, the coordinate plane's normal as direction)."""
    if g.kind == "plane":
        return PLANE
    if g.kind in ("line", "cylinder", "cone", "circle_space"):
        return AXIS
    return POINT


@dataclass(frozen=True)
class Frame:
    """Origin (B x 3, mm) and rotation (B x 3 x 3, columns x, y, z in machine coordinates)."""

    origin_mm: np.ndarray
    R: np.ndarray

    def to_frame(self, x_mm) -> np.ndarray:
        """Machine coordinates (B x ... x 3) -> frame coordinates."""
        x = np.asarray(x_mm, float)
        o = self.origin_mm.reshape((-1,) + (1,) * (x.ndim - 2) + (3,))
        return np.einsum("b...i,bij->b...j", x - o, self.R)

    def direction(self, v) -> np.ndarray:
        return np.einsum("bi,bij->bj", np.asarray(v, float), self.R)


def _dot(a, b):
    return np.einsum("bi,bi->b", a, b)


def _angle_deg(sines) -> float:
    """The smallest angle (deg) of the sines of the batch."""
    return float(np.degrees(np.arcsin(np.clip(np.min(sines), 0.0, 1.0))))


def _unit(v, what):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n < 1e-12):
        raise DegenerateGeometryError(f"datum frame: {what}")
    return v / n


def datum_frame(primary: Geometry, secondary: Geometry | None = None,
                tertiary: Geometry | None = None) -> Frame:
    """The frame of the module docstring.  Missing secondary/tertiary leave the corresponding
    degrees of freedom at a convention (x: the smallest rotation of e_z onto z at the first
    draw; origin: the primary's locating point moved least) -- fine for orientation, not for
    position."""
    if role(primary) != PLANE:
        raise ModelError("datum frame: the primary datum must be a plane (an axis or point as "
                         "primary datum is not supported)")
    z = -_unit(primary.direction, "primary normal is zero")
    pA = primary.point
    B = z.shape[0]
    x = None
    rows, rhs = [z], [_dot(z, pA)]
    origin = None
    if secondary is not None:
        rs = role(secondary)
        if rs == PLANE:
            nB = secondary.direction
            across = nB - _dot(nB, z)[:, None] * z
            if np.any(np.linalg.norm(across, axis=-1) < _MIN_SIN):
                raise DegenerateGeometryError(
                    "datum frame: the secondary datum plane is parallel to the primary (within "
                    f"{MIN_DATUM_ANGLE_DEG:g} deg; angle {_angle_deg(np.linalg.norm(across, axis=-1)):.3g} deg): it "
                    "fixes no direction of the frame")
            x = -_unit(across, "the secondary datum plane is parallel to the primary")
            rows.append(nB)
            rhs.append(_dot(nB, secondary.point))
        else:
            v = z if rs == POINT else secondary.direction
            den = _dot(v, z)
            if np.any(np.abs(den) < _MIN_SIN):
                raise DegenerateGeometryError("datum frame: the secondary datum axis is parallel "
                                              f"to the primary datum plane (within {MIN_DATUM_ANGLE_DEG:g} deg)")
            origin = secondary.point + (_dot(z, pA - secondary.point) / den)[:, None] * v
    if tertiary is not None:
        if secondary is None:
            raise ModelError("datum frame: a tertiary datum needs a secondary datum")
        if x is None:    # secondary axis/point: the tertiary clocks x
            q = tertiary.point - origin
            x = _unit(q - _dot(q, z)[:, None] * z,
                      "the tertiary datum lies on the secondary datum axis")
        elif role(tertiary) == PLANE:
            rows.append(tertiary.direction)
            rhs.append(_dot(tertiary.direction, tertiary.point))
        else:
            y = np.cross(z, x)
            rows.append(y)
            rhs.append(_dot(y, tertiary.point))
    if x is None:
        x = np.broadcast_to(frame_from_axis(z[0])[:, 0], (B, 3)).copy()
        x = _unit(x - _dot(x, z)[:, None] * z, "no x axis")
    y = np.cross(z, x)
    R = np.stack([x, y, z], axis=-1)
    if origin is None:
        Amat = np.stack(rows, axis=1)           # B x r x 3
        b = np.stack(rhs, axis=1)               # B x r
        if Amat.shape[1] == 3:
            Aunit = Amat / np.linalg.norm(Amat, axis=-1, keepdims=True)
            det = np.abs(np.linalg.det(Aunit))
            if np.any(det < _MIN_SIN):
                raise DegenerateGeometryError(
                    "datum frame: the three datum planes do not meet in a point: the tertiary is "
                    f"parallel to the line of the other two (within {MIN_DATUM_ANGLE_DEG:g} deg; angle "
                    f"{_angle_deg(det):.3g} deg)")
            origin = np.linalg.solve(Amat, b[..., None])[..., 0]
        else:
            r = b - np.einsum("bri,bi->br", Amat, pA)
            AAt = np.einsum("bri,bsi->brs", Amat, Amat)
            origin = pA + np.einsum("bri,br->bi", Amat, np.linalg.solve(AAt, r[..., None])[..., 0])
    return Frame(origin_mm=origin, R=R)
