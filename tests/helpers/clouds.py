"""The model parameters, probes and point clouds that the core and locator tests share (Forbes 2025:
the six influence factors of eq. (28))."""

from __future__ import annotations

import numpy as np

from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.model import MPE1 as MPE1  # Forbes 2025 Table 3, defined once in the core

# -- every factor on, three probes (the blocked, low-rank, Monte Carlo, udf and Dask tests) ---------

PARAMS = pc.Parameters(sigma_R_um=0.2, sigma_S_ppm=0.7, sigma_Sa_ppm=0.8, sigma_Q_ppm=0.9, sigma_PQ_um=0.2,
                       sigma_ET_um=0.3, lambda_ET_mm=150, sigma_ER_urad=4.0, lambda_ER_mm=350,
                       sigma_P0_um=0.1, sigma_P_um=0.15, lambda_P=0.5)

PROBES = (pc.Probe("P1", (0, 0, -50.0)),
          pc.Probe("P2", (10, 40.0, -30.0), sigma_PQ_um=0.3, sigma_P0_um=0.05, lambda_P=0.7),
          pc.Probe("P3", (-20, 5, -10), sigma_P_um=0.0))


def random_cloud(m: int, seed: int = 3) -> pc.PointCloud:
    rng = np.random.default_rng(seed)
    X = rng.uniform(-300, 300, (m, 3))
    N = rng.normal(size=(m, 3))
    N /= np.linalg.norm(N, axis=1)[:, None]
    return pc.PointCloud(X, N, rng.integers(0, 3, m), PROBES)


def sphere_cloud(m: int, seed: int = 1) -> pc.PointCloud:
    rng = np.random.default_rng(seed)
    z = rng.uniform(-0.2, 1, m)
    th = rng.uniform(0, 2 * np.pi, m)
    N = np.column_stack([np.sqrt(1 - z * z) * np.cos(th), np.sqrt(1 - z * z) * np.sin(th), z])
    X = np.array([100.0, -50.0, 20.0]) + 12.5 * N + rng.normal(scale=2e-3, size=(m, 3))
    return pc.PointCloud(X, N, np.arange(m) % 2, PROBES[:2])


def rel_err(A, B) -> float:
    """Largest difference relative to the largest entry (the matrices' scale)."""
    scale = np.max(np.abs(B))
    return 0.0 if scale == 0 else float(np.max(np.abs(A - B)) / scale)


# -- the locator's machine: the MPE1 set of Table 3 and its probe sets ------------------------------


ONE = (pc.Probe("P1", (0.0, 0.0, -50.0)),)

THREE = (pc.Probe("P1", (0.0, 0.0, -50.0)), pc.Probe("P2", (150.0, 0.0, -50.0)), pc.Probe("P3", (0.0, 150.0, -50.0)))

PAIR = (pc.Probe("P1", (0.0, 20.0, -30.0)), pc.Probe("P2", (0.0, -20.0, -30.0)))
