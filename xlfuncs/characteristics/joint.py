"""The joint fit of a task's features: every feature fitted to its own points of one joint point
set (Forbes 2022), their sensitivity matrices G_A|X (eq. (8)) stacked row-wise into the joint G,
and V_A = G V_X G^T of all features' local parameters (Forbes 2025 section 5.6), whose
off-diagonal blocks are the correlations between features measured by one CMM."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from .. import features as ft
from ..errors import ModelError, about
from .specs import FeatureSpec


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
    for k, s in enumerate(specs):
        idx = np.asarray(s.indices, int)
        if idx.size == 0 or idx.min() < 0 or idx.max() >= m:
            raise about(ModelError(f"feature {s.name}: point indices out of range"), "features", k)
        if len(set(idx.tolist())) != idx.size:
            raise about(ModelError(f"feature {s.name}: a point is listed twice"), "features", k)
        try:
            f = ft.fit(s.element, X[idx], normals=N[idx], axis_hint=s.axis_hint,
                       circle_plane=s.circle_plane if s.element == "circle" else "xy")
        except ModelError as err:
            raise about(err, "features", k, f"feature {s.name}") from None
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
