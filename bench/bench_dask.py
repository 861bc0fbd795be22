"""The same kernels on a local multi-process Dask cluster (issue 26): ``distributed.LocalCluster``
with 2 worker processes (1 thread each), reached through its scheduler address as a remote
cluster would be, against the single-process path, in one process (one BLAS thread everywhere).

* ``diagnose``  length records (ISO 10360-2 style, planted squareness_xy and ECZ; the passes of
                the structured length covariance, xlfuncs.locator.structured_lengths, as Dask tasks);
* ``va``        per-factor V_A of a sphere fitted to m points, low-rank GP factors (the Nyström
                projections of xlfuncs.lowrank as Dask tasks) and exact blocked sums.

Reported: wall times of both, the largest relative difference over chi-square, estimates, their
u and the records' u (diagnose) or every V_A factor (va).  The 2-core machine is shared with other
jobs, so a cluster on it cannot be faster; the rows show the numbers are the same.  Results:
bench/results/dask.md.  Usage: ``python bench/bench_dask.py [--records N] [--points M]``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402


def rel(a, b) -> float:
    a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)) if a.size else 0.0


def main(argv: list[str]) -> int:
    import distributed

    from cmmwb.xlfuncs import blocked as bl
    from cmmwb.xlfuncs import features as ft
    from cmmwb.xlfuncs import pointcloud as pc
    from cmmwb.xlfuncs.distributed import DaskBackend
    from cmmwb.xlfuncs.locator import diagnose as dg
    from cmmwb.xlfuncs.locator import simulate as sm

    n, m = 20_000, 100_000
    for a in argv:
        if a.startswith("--records="):
            n = int(a.split("=")[1])
        if a.startswith("--points="):
            m = int(a.split("=")[1])
    rows = []
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        from cmmwb.xlfuncs.model import MPE1  # Forbes 2025 Table 3
        PROBES = (pc.Probe("P1", (0.0, 0.0, -50.0)), pc.Probe("P2", (150.0, 0.0, -50.0)),
                  pc.Probe("P3", (0.0, 150.0, -50.0)))
        L = sm.iso10360(PROBES, repeats=-(-n // 70), fractions=tuple(np.linspace(0.07, 0.7, 10)), hours=8.0)
        rec = sm.simulate(L, MPE1, {"squareness_xy": 15.0, "ECZ": 200.0}, seed=7, temperature_C=(19.8, 21.0))
        model = dg.Model(MPE1, PROBES, True)
        t = time.perf_counter()
        loc = dg.diagnose(rec, model, structured=True)
        t_loc = time.perf_counter() - t
        with DaskBackend(c.scheduler_address) as be:
            t = time.perf_counter()
            rem = dg.diagnose(rec, model, structured=True, backend=be)
            t_rem = time.perf_counter() - t
        diff = max(rel(rem.chi2_before, loc.chi2_before), rel(rem.chi2_after, loc.chi2_after), rel(rem.beta, loc.beta),
                   rel(np.diag(rem.cov_beta), np.diag(loc.cov_beta)), rel(rem.u_obs, loc.u_obs),
                   rel([g["chi2"] for g in rem.groups], [g["chi2"] for g in loc.groups]))
        rows.append((f"diagnose, {rec.n:,} length records", t_loc, t_rem, diff,
                     f"{' + '.join(loc.chosen)} / {' + '.join(rem.chosen)}"))
        print(rows[-1], flush=True)
        rng = np.random.default_rng(1)
        params = pc.Parameters(0.2, 0.7, 0.7, 0.7, 0.2, 0.2, 200, 4.0, 400, 0.1, 0.1, 0.5)
        probes = (pc.Probe("P1", (0, 0, -50.0)), pc.Probe("P2", (0, 40.0, -30.0), sigma_PQ_um=0.3))
        for method, mm in (("lowrank", m), ("exact", min(m, 20_000))):
            z = rng.uniform(-0.3, 1, mm)
            th = rng.uniform(0, 2 * np.pi, mm)
            N = np.column_stack([np.sqrt(1 - z * z) * np.cos(th), np.sqrt(1 - z * z) * np.sin(th), z])
            X = np.array([200.0, 150.0, 50.0]) + 25.0 * N + rng.normal(scale=1e-3, size=(mm, 3))
            cloud = pc.PointCloud(X, N, np.arange(mm) % 2, probes)
            f = ft.fit("sphere", X, normals=N)
            G = ft.G_A_X(f)
            t = time.perf_counter()
            loc = bl.propagate_cloud(f, cloud, params, G=G, method=method)
            t_loc = time.perf_counter() - t
            with DaskBackend(c.scheduler_address) as be:
                t = time.perf_counter()
                rem = bl.propagate_cloud(f, cloud, params, G=G, method=method, backend=be)
                t_rem = time.perf_counter() - t
            diff = max(rel(rem.V_local[k], loc.V_local[k]) for k in (*pc.FACTORS, "total"))
            rows.append((f"V_A of a sphere, {mm:,} points, {method}", t_loc, t_rem, diff, ""))
            print(rows[-1], flush=True)
    load = os.getloadavg()[0]
    lines = ["Measured by `python bench/bench_dask.py` on the 2-core machine shared with other jobs (load "
             f"average {load:.1f} after the run; 2.0 = both cores busy).  Cluster: "
             "`distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True)`, used through its "
             "scheduler address (`DaskBackend(address)`, as `CMMWB_SCHEDULER=tcp://host:8786` does).", "",
             "| computation | one process / s | Dask, 2 worker processes / s | largest relative difference | chosen (local / Dask) |",
             "|---|---|---|---|---|"]
    for name, a, b, d, ch in rows:
        lines.append(f"| {name} | {a:.1f} | {b:.1f} | {d:.1e} | {ch} |")
    out = ROOT / "bench" / "results" / "dask.md"
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
