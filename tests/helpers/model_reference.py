"""Reference implementations for the tests: the literal formulas, slow and dense, that the
production paths of the six-factor model are checked against (nothing here ships)."""

from __future__ import annotations

import numpy as np

from cmmwb.xlfuncs import pointcloud as pc


def length_covariance_dense(cloud: pc.PointCloud, params: pc.Parameters, I, J) -> np.ndarray:
    """G V_X G^T with the dense V_X of Forbes 2025 eq. (28) and g_a = [-n_a; n_a] of eq. (29)."""
    V = pc.V_X(cloud, params)
    d = cloud.X_mm[J] - cloud.X_mm[I]
    na = d / np.linalg.norm(d, axis=1)[:, None]
    G = np.zeros((len(I), 3 * cloud.m))
    for a in range(len(I)):
        G[a, 3 * I[a]:3 * I[a] + 3] -= na[a]
        G[a, 3 * J[a]:3 * J[a] + 3] += na[a]
    return G @ V @ G.T
