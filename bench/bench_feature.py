"""Benchmarks of the feature task (Forbes 2022 fits under the Forbes 2025 V_X).

1. Core: fit plus the per-factor V_A of a 2,000-point cylinder scan with the full six-factor
   Gaussian-process V_X (two probes):  python bench/bench_feature.py
2. Workbook: build and recalculate cylinder workbooks of m points with native V_X formulas in
   `formulas` and LibreOffice, to measure the native-formula limit:
   python bench/bench_feature.py --workbooks 24 48 72 100

Prints one line per measurement; the numbers quoted in docs/benchmarks.md and in
generator/feature/book.py (FEATURE_NATIVE_MAX_POINTS) come from here.
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cmmwb.xlfuncs import features, partial, pointcloud  # noqa: E402
from cmmwb.xlfuncs.model import MPE1 as PARAMS  # noqa: E402  (Forbes 2025 Table 3)


def cylinder_scan(m_theta: int, m_z: int, seed: int = 1):
    """A bore of radius 40 mm, 120 mm long, scanned on m_z rings of m_theta points, with form
    error and noise; two probes (the lower half of the rings with an angled stylus)."""
    s = partial.sample("cylinder_patch", center_mm=[300.0, 200.0, -150.0], axis=[0.01, -0.02, 1.0],
                       r0_mm=40.0, arc_deg=360.0, half_height_mm=60.0, n_theta=m_theta, n_z=m_z)
    rng = np.random.default_rng(seed)
    X = s.X_mm + s.N * rng.normal(scale=0.001, size=(s.m, 1))
    probes = (pointcloud.Probe("P1", (0.0, 0.0, -50.0)), pointcloud.Probe("P2", (30.0, 0.0, -40.0)))
    k = (np.arange(s.m) % m_z < m_z // 2).astype(int)
    return pointcloud.PointCloud(X, s.N, k, probes), s


def bench_core(m_theta: int = 100, m_z: int = 20) -> None:
    """Fit + per-factor V_A, first without forming V_X (xlfuncs.blocked, what `cmmwb build` uses
    beyond 300 points; its peak memory is measured before the dense path runs), then with the
    dense V_X of eq. (28), and the largest relative difference of the two V_A."""
    from cmmwb.xlfuncs import blocked

    cloud, s = cylinder_scan(m_theta, m_z)
    t0 = time.perf_counter()
    f = features.fit("cylinder", cloud.X_mm, normals=cloud.N)
    t1 = time.perf_counter()
    G = features.G_A_X(f)
    t2 = time.perf_counter()
    unc_b = blocked.propagate_cloud(f, cloud, PARAMS, G=G)
    t3 = time.perf_counter()
    peak_blocked = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20
    comps = pointcloud.V_X_components(cloud, PARAMS)
    t4 = time.perf_counter()
    unc = features.propagate(f, comps, G=G)
    t5 = time.perf_counter()
    peak_dense = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20
    diff = max(float(np.max(np.abs(unc_b.V[k] - unc.V[k])) / np.max(np.abs(unc.V[k])))
               for k in unc.V if np.max(np.abs(unc.V[k])) > 0)
    u = dict(zip(f.names, unc_b.u()))
    lines: list[str] = []

    def say(text: str) -> None:
        lines.append(text)
        print(text, flush=True)

    say(f"cylinder scan m = {cloud.m} points ({m_z} rings x {m_theta}), two probes, full GP V_X "
          f"(3m = {3 * cloud.m}):")
    rows = [(f"fit (Gauss-Newton, {f.iterations} iterations, multi-start)", t1 - t0),
            (f"G_A|X ({f.n} x {3 * cloud.m})", t2 - t1),
            ("V_A per factor without V_X (xlfuncs.blocked)", t3 - t2),
            ("total: fit + per-factor V_A (blocked, what build uses)", t3 - t0),
            (f"dense: V_X components (6 x {3 * cloud.m}^2, xlfuncs.pointcloud)", t4 - t3),
            ("dense: V_A per factor (G V_X,f G^T, 6 factors)", t5 - t4),
            ("total: fit + per-factor V_A (dense)", (t1 - t0) + (t2 - t1) + (t5 - t3))]
    for label, dt in rows:
        say(f"  {label:<58s}{dt:8.3f} s")
    say(f"  peak RSS {peak_blocked:.2f} GB after the blocked path, {peak_dense:.2f} GB after the dense one; "
          f"largest relative difference of V_A: {diff:.1e}")
    say(f"  u(r0) = {u['r0_mm'] * 1e3:.4f} µm, u(x_A) = {u['x_A_mm'] * 1e3:.4f} µm; components (µm): "
          + ", ".join(f"{fac} {unc_b.u(fac)[f.names.index('r0_mm')] * 1e3:.4f}" for fac in pointcloud.FACTORS))
    out = Path(__file__).resolve().parent / "results" / "feature.md"
    out.write_text("Measured by `python bench/bench_feature.py` on the 2-core machine "
                   f"(1-minute load average at the end: {os.getloadavg()[0]:.1f}).\n\n```\n"
                   + "\n".join(lines) + "\n```\n")


def bench_workbooks(sizes: list[int], engines: list[str]) -> None:
    from cmmwb.generator.cli import build_task
    from cmmwb.generator.workbook.recalc import recalculate

    from tests.helpers.tasks import parameters_toml

    for m in sizes:
        n_z = 4
        n_theta = max(3, math.ceil(m / n_z))
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            task = tmp / "cyl.toml"
            task.write_text(f'''[task]
kind = "feature"
name = "cyl{m}"
[feature]
type = "cylinder"
[sampling]
pattern = "cylinder_patch"
r0_mm = 25.0
arc_deg = 360.0
half_height_mm = 20.0
n_theta = {n_theta}
n_z = {n_z}
{parameters_toml(PARAMS)}[[probes]]
id = "P1"
offset_mm = [0.0, 0.0, -50.0]
''')
            t0 = time.perf_counter()
            _, files = build_task(task, tmp / "out", plots=False)
            tb = time.perf_counter() - t0
            book = [p for p in files if p.suffix == ".xlsx"][0]
            line = f"workbook m = {n_theta * n_z:4d} points: build {tb:6.1f} s, {book.stat().st_size / 1e6:5.1f} MB"
            for eng in engines:
                t0 = time.perf_counter()
                recalculate(book, eng)
                line += f", {eng} {time.perf_counter() - t0:6.1f} s"
            print(line, flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workbooks", type=int, nargs="*", help="point counts for the workbook benchmark")
    ap.add_argument("--engines", nargs="*", default=["formulas", "libreoffice"])
    ap.add_argument("--m-theta", type=int, default=100)
    ap.add_argument("--m-z", type=int, default=20)
    args = ap.parse_args()
    if args.workbooks:
        bench_workbooks(args.workbooks, args.engines)
    else:
        bench_core(args.m_theta, args.m_z)


if __name__ == "__main__":
    main()
