"""Results do not depend on the CPU: numpy's BLAS (OpenBLAS) picks its kernels by CPU, and a
seeded simulation must draw the same records under every kernel.

A regular ball plate has Gaussian-process covariances with degenerate eigenvalues (its symmetry);
the eigenvectors of such an eigenvalue are any basis of their space, and which basis comes out
depends on the kernel.  A draw V diag(w)^(1/2) z therefore changed with the CPU (chi2 of the
same seeded set: 1838.45 under SkylakeX, 1745.27 under Haswell); the symmetric square root
K^(1/2) z is unique and does not."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from cmmwb.xlfuncs.locator import simulate as sm

SCRIPT = r"""
import json, sys
import numpy as np
import threadpoolctl
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.locator import diagnose as dg, simulate as sm
from cmmwb.xlfuncs.model import MPE1  # Forbes 2025 Table 3
ONE = (pc.Probe("P1", (0.0, 0.0, -50.0)),)
rec = sm.simulate(sm.layout("ballplate", ONE), MPE1, {}, seed=5)
j = dg.diagnose(rec, dg.Model(MPE1, ONE, True)).to_json()
arch = sorted({str(i.get("architecture")) for i in threadpoolctl.threadpool_info()})
print(json.dumps({"arch": arch, "X_mm": rec.X_mm.tolist(), "chi2_before": j["chi2_before"]}))
"""


MC_SCRIPT = r"""
import json
import numpy as np
import threadpoolctl
from cmmwb.xlfuncs import montecarlo as mc, pointcloud as pc
from cmmwb.xlfuncs.model import MPE1 as params  # Forbes 2025 Table 3
g = np.arange(6) * 60.0                      # a 6 x 6 grid of points: degenerate kernel spectra
X = np.array([[x, y, 0.0] for x in g for y in g])
N = np.tile([0.0, 0.0, 1.0], (len(X), 1))
cloud = pc.PointCloud(X, N, np.zeros(len(X), dtype=int), (pc.Probe("P1", (0.0, 0.0, -50.0)),),
                      tuple(f"Q{i}" for i in range(len(X))))
d = mc.PointCloudSampler(cloud, params).draw(3, np.random.default_rng(11))
arch = sorted({str(i.get("architecture")) for i in threadpoolctl.threadpool_info()})
print(json.dumps({"arch": arch, "draws": {f: v.tolist() for f, v in d.items()}}))
"""


def _run(coretype: str | None, script: str = SCRIPT) -> dict:
    env = dict(os.environ)
    env.pop("OPENBLAS_CORETYPE", None)
    if coretype:
        env["OPENBLAS_CORETYPE"] = coretype
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                         timeout=300, check=True)
    return json.loads(out.stdout)


def test_a_seeded_ball_plate_simulation_is_the_same_under_two_blas_kernels():
    a, b = _run(None), _run("Prescott")       # Prescott: SSE3 kernels, on every x86-64
    if a["arch"] == b["arch"] or a["arch"] == ["None"]:
        pytest.skip(f"one BLAS kernel only here ({a['arch']})")
    Xa, Xb = np.array(a["X_mm"]), np.array(b["X_mm"])
    assert np.max(np.abs(Xa - Xb)) * 1000 < 1e-9, "records differ in µm"
    assert a["chi2_before"] == pytest.approx(b["chi2_before"], rel=1e-9)


def test_seeded_monte_carlo_draws_are_the_same_under_two_blas_kernels():
    a, b = _run(None, MC_SCRIPT), _run("Prescott", MC_SCRIPT)
    if a["arch"] == b["arch"] or a["arch"] == ["None"]:
        pytest.skip(f"one BLAS kernel only here ({a['arch']})")
    for f in a["draws"]:
        da, db = np.array(a["draws"][f]), np.array(b["draws"][f])
        assert np.max(np.abs(da - db)) <= 1e-9 * max(np.max(np.abs(da)), 1e-12), f


def test_a_gaussian_process_draw_is_the_symmetric_square_root_whatever_the_eigenbasis():
    """The draw equals K^(1/2) z computed in a rotated basis (R K R^T has other eigenvectors)."""
    g = np.arange(5) * 100.0
    P = np.array([[x, y, 0.0] for x in g for y in g])          # a 5 x 5 plate: degenerate spectrum
    K = 0.2**2 * np.exp(-np.sum((P[:, None] - P[None]) ** 2, -1) / 200.0**2)
    z = np.random.default_rng(3).standard_normal((len(P), 1))
    R, _ = np.linalg.qr(np.random.default_rng(4).standard_normal((len(P), len(P))))
    w, V = np.linalg.eigh(R @ K @ R.T)
    w = np.where(w > 1e-13 * w[-1], w, 0.0)
    expected = R.T @ (V @ (np.sqrt(w)[:, None] * (V.T @ (R @ z))))
    drawn = sm._gp(P, 0.2, 200.0, np.random.default_rng(3))
    assert np.allclose(drawn, expected, rtol=0, atol=1e-9 * 0.2)
