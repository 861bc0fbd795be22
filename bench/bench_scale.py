"""Benchmarks of the blocked point-cloud computations (issue 6).  Run: python bench/bench_scale.py [case ...]

1. all-pairs distance u with its six components, m = 3000 (4.5 million distances), two probes,
   every factor                                                       target < 1.5 s, < 600 MB
2. per-factor V_A of a sphere fitted to m = 20,000 points, full GP V_X (never formed)
                                                                      target < 30 s, < 2 GB
3. the same for a cylinder, m = 20,000                                target < 30 s, < 2 GB
4. the same sphere on the local Dask backend (xlfuncs.distributed), for comparison
5. the large workbook: build of a task with m = 2,000 points and 2,000 distances, and its full
   LibreOffice recalculation (every Results value visible)

Every case runs REPEATS times, each in a fresh subprocess so that its peak memory (ru_maxrss,
including the ~70 MB of the interpreter and numpy) is its own.  The machine has 2 cores shared
with other jobs, so the best and the median are reported, with the load average at the start.
Results are printed and written to bench/results/scale.md.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REPEATS = int(os.environ.get("BENCH_REPEATS", "5"))

SETUP_FEATURE = """
    import time
    import numpy as np
    from cmmwb.xlfuncs import pointcloud as pc, features as ft, blocked as bl
    rng = np.random.default_rng(1)
    m = 20_000
    params = pc.Parameters(0.2, 0.7, 0.7, 0.7, 0.2, 0.2, 200, 4.0, 400, 0.1, 0.1, 0.5)
    probes = (pc.Probe("P1", (0, 0, -50.0)), pc.Probe("P2", (0, 40.0, -30.0), sigma_PQ_um=0.3))
"""
SPHERE = SETUP_FEATURE + """
    z = rng.uniform(-0.3, 1, m); th = rng.uniform(0, 2 * np.pi, m)
    N = np.column_stack([np.sqrt(1 - z * z) * np.cos(th), np.sqrt(1 - z * z) * np.sin(th), z])
    X = np.array([200.0, 150.0, 50.0]) + 25.0 * N + rng.normal(scale=1e-3, size=(m, 3))
    element = "sphere"
"""
CYLINDER = SETUP_FEATURE + """
    th = rng.uniform(0, 2 * np.pi, m); h = rng.uniform(-40, 40, m)
    N = np.column_stack([np.cos(th), np.sin(th), 0 * th])
    X = np.column_stack([200 + 20 * np.cos(th), 150 + 20 * np.sin(th), 50 + h]) + rng.normal(scale=1e-3, size=(m, 3))
    element = "cylinder"
"""
PROPAGATE = """
    cloud = pc.PointCloud(X, N, np.arange(m) % 2, probes)
    t = time.perf_counter()
    f = ft.fit(element, X, normals=N)
    unc = bl.propagate_cloud(f, cloud, params, backend=BACKEND)
    seconds = time.perf_counter() - t
    extra = {"u": [float(x) for x in unc.u()], "names": list(f.names)}
"""

CASES = {
    "all_pairs_m3000": """
        import time
        import numpy as np
        from cmmwb.xlfuncs import pointcloud as pc
        rng = np.random.default_rng(1)
        m = 3000
        X = rng.uniform(0, 800, (m, 3)); N = rng.normal(size=(m, 3)); N /= np.linalg.norm(N, axis=1)[:, None]
        probes = (pc.Probe("P1", (0, 0, -50.0)), pc.Probe("P2", (0, 40.0, -30.0), sigma_PQ_um=0.3))
        cloud = pc.PointCloud(X, N, np.arange(m) % 2, probes)
        params = pc.Parameters(0.2, 0.7, 0.7, 0.7, 0.2, 0.2, 200, 4.0, 400, 0.1, 0.1, 0.5)
        t = time.perf_counter()
        r = pc.distance_components(cloud, params)
        seconds = time.perf_counter() - t
        assert r["u_um"].shape == (m * (m - 1) // 2,)
        extra = {}
    """,
    "V_A_sphere_m20000": "BACKEND = None\n" + textwrap.dedent(SPHERE) + textwrap.dedent(PROPAGATE),
    "V_A_cylinder_m20000": "BACKEND = None\n" + textwrap.dedent(CYLINDER) + textwrap.dedent(PROPAGATE),
    "V_A_sphere_m20000_dask": textwrap.dedent(SPHERE) + """
from cmmwb.xlfuncs.distributed import DaskBackend
with DaskBackend() as BACKEND:
""" + textwrap.indent(textwrap.dedent(PROPAGATE), "    "),
    "large_book_m2000": """
        import time, tempfile
        from pathlib import Path
        from tests.helpers.tasks import write_large_task
        from cmmwb.generator.cli import build_task
        from cmmwb.generator.workbook.recalc import recalculate, results_rows
        tmp = Path(tempfile.mkdtemp())
        task = write_large_task(tmp, 2000, "plate_m2000")
        t = time.perf_counter()
        results, _ = build_task(task, tmp / "out", plots=False)
        build_s = time.perf_counter() - t
        t = time.perf_counter()
        rows = results_rows(recalculate(tmp / "out" / "plate_m2000.xlsx", "libreoffice"))
        seconds = time.perf_counter() - t
        assert len(rows) == len(results["distances"]) == 2000
        extra = {"build_s": build_s, "xlsx_MB": (tmp / "out" / "plate_m2000.xlsx").stat().st_size / 2**20}
    """,
}
TARGETS = {"all_pairs_m3000": "< 1.5 s, < 600 MB", "V_A_sphere_m20000": "< 30 s, < 2 GB",
           "V_A_cylinder_m20000": "< 30 s, < 2 GB", "V_A_sphere_m20000_dask": "(comparison)",
           "large_book_m2000": "LibreOffice recalc; test budget < 60 s"}

TAIL = """
import resource, json
print("RESULT", json.dumps({"seconds": seconds, "peak_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                            **extra}))
"""


def run(name: str) -> dict:
    code = textwrap.dedent(CASES[name]) + TAIL
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{name} failed:\n{p.stderr}")
    line = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT")][-1]
    return json.loads(line[len("RESULT "):])


def main(names=None) -> None:
    head = ["| case | time / s best | time / s median | peak MB best | peak MB median | load at start | target | notes |",
            "|---|---|---|---|---|---|---|---|"]
    out = ROOT / "bench" / "results" / "scale.md"
    rows = {}
    if out.exists():   # keep the cases not run this time
        for line in out.read_text().splitlines():
            name = line.split("|")[1].strip() if line.startswith("| ") else ""
            if name in CASES:
                rows[name] = line
    for name in names or CASES:
        load = os.getloadavg()[0]
        rs = [run(name) for _ in range(REPEATS)]
        t = [r["seconds"] for r in rs]
        mem = [r["peak_MB"] for r in rs]
        note = ""
        if "u" in rs[0]:
            note = "u (parameter units): " + ", ".join(f"{n} {u:.3g}" for n, u in zip(rs[0]["names"], rs[0]["u"]))
        if "build_s" in rs[0]:
            note = (f"time = LibreOffice recalc; build {min(r['build_s'] for r in rs):.1f} s best, "
                    f"{statistics.median(r['build_s'] for r in rs):.1f} s median; xlsx {rs[0]['xlsx_MB']:.1f} MB")
        rows[name] = (f"| {name} | {min(t):.2f} | {statistics.median(t):.2f} | {min(mem):.0f} | "
                      f"{statistics.median(mem):.0f} | {load:.1f} | {TARGETS[name]} | {note} |")
        print(rows[name], flush=True)
    out.write_text(
        f"Measured by `python bench/bench_scale.py` on the 2-core machine shared with other jobs "
        f"({REPEATS} runs per case, each in a fresh process; peak memory = ru_maxrss of that process, "
        "interpreter and numpy included; 'load at start' = 1-minute load average, 2.0 = both cores "
        "busy).\n\n" + "\n".join(head + [rows[n] for n in CASES if n in rows]) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:] or None)
