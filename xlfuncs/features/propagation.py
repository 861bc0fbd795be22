"""The point-cloud V_X propagated to a fitted feature's parameters per influence factor:
V_A = G_A|X V_X G_A|X^T, V_A = sum_f G_A|X V_X,f G_A|X^T (Forbes 2025 section 5.6), and the
reported parameters' T V_A T^T."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..errors import ModelError
from .fitting import G_A_X, FeatureFit

#: 1 µm^2 in mm^2
UM2_TO_MM2 = 1e-6


# --------------------------------------------------------------------------------------------
# propagation of V_X per influence factor (Forbes 2025 section 5.6)
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FeatureUncertainty:
    """V_A of a fitted feature, total and per influence factor.

    ``V_local[f]`` (n x n) and ``V[f]`` (global, T V_local T^T) are in the parameters' units
    (mm^2, rad^2, ...); ``"total"`` is their sum over the factors.
    """

    fit: FeatureFit
    G: np.ndarray                         # G_A|X, n x 3m, local parameter unit per mm
    V_local: dict[str, np.ndarray]
    V: dict[str, np.ndarray]
    factors: tuple[str, ...]
    #: the low-rank evaluation's ranks and error bounds (xlfuncs.lowrank.Approximation), or None
    approximation: object = None

    def u(self, factor: str = "total") -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.V[factor]), 0.0, None))

    def u_local(self, factor: str = "total") -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.V_local[factor]), 0.0, None))


def propagate(f: FeatureFit, V_X_um2: Mapping[str, np.ndarray] | np.ndarray,
              *, G: np.ndarray | None = None) -> FeatureUncertainty:
    """V_A = G_A|X V_X G_A|X^T for every factor of a V_X decomposition (µm^2, 3m x 3m,
    interleaved x1, y1, z1, ...).  A single matrix is treated as one factor named "V_X"."""
    comps = {"V_X": V_X_um2} if isinstance(V_X_um2, np.ndarray) else dict(V_X_um2)
    if not comps:
        raise ModelError("no V_X components to propagate")
    G = G_A_X(f) if G is None else G
    V_local, V = {}, {}
    total_l = np.zeros((f.n, f.n))
    for name, Vx in comps.items():
        Vx = np.asarray(Vx, dtype=float)
        if Vx.shape != (3 * f.m, 3 * f.m):
            raise ModelError(f"V_X component {name}: expected a {3 * f.m} x {3 * f.m} matrix, "
                             f"got {Vx.shape[0]} x {Vx.shape[1] if Vx.ndim > 1 else 1}")
        if not np.all(np.isfinite(Vx)):
            raise ModelError(f"V_X component {name} has non-finite entries")
        Va = (G @ Vx @ G.T) * UM2_TO_MM2
        Va = 0.5 * (Va + Va.T)
        V_local[name] = Va
        V[name] = f.T @ Va @ f.T.T
        total_l = total_l + Va
    V_local["total"] = total_l
    V["total"] = f.T @ total_l @ f.T.T
    return FeatureUncertainty(fit=f, G=G, V_local=V_local, V=V, factors=tuple(comps))
