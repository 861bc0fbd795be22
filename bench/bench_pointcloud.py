"""Benchmarks of the point-cloud path (Forbes 2025).  Run: python bench/bench_pointcloud.py

1. build the m = 52 step-gauge workbook (load + compute + write, no plots)   target < 1 s
2. all-pairs distance u with components, m = 3000, two probes, every factor  target < 1.5 s, < 600 MB
3. LibreOffice full recalculation of the m = 52 workbook (and `formulas` for comparison)

Each case runs in a fresh subprocess so that its peak memory (ru_maxrss) is its own.
Results are printed and written to bench/results/pointcloud.md.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CASES = {
    "build_stepgauge_m52": """
        import time, tomllib
        from pathlib import Path
        from cmmwb.generator.pointcloud import job
        from cmmwb.generator.taskfile import read_toml
        p = Path("generator/examples/stepgauge_II_MPE1.toml")
        import tempfile
        out = Path(tempfile.mkdtemp())
        job.write_book(job.load(p, read_toml(p)), job.compute(job.load(p, read_toml(p))), out / "w.xlsx")  # warm-up
        t = time.perf_counter()
        for _ in range(3):
            task = job.load(p, read_toml(p))
            res = job.compute(task)
            job.write_book(task, res, out / "w.xlsx")
        seconds = (time.perf_counter() - t) / 3
    """,
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
    """,
    "recalc_libreoffice_m52": """
        import time, tempfile
        from pathlib import Path
        from cmmwb.generator.cli import build_task
        from cmmwb.generator.workbook.recalc import recalculate
        out = Path(tempfile.mkdtemp())
        build_task(Path("generator/examples/stepgauge_II_MPE1.toml"), out, plots=False)
        t = time.perf_counter()
        recalculate(out / "stepgauge_II_MPE1.xlsx", "libreoffice")
        seconds = time.perf_counter() - t
    """,
    "recalc_formulas_m52": """
        import time, tempfile
        from pathlib import Path
        from cmmwb.generator.cli import build_task
        from cmmwb.generator.workbook.recalc import recalculate
        out = Path(tempfile.mkdtemp())
        build_task(Path("generator/examples/stepgauge_II_MPE1.toml"), out, plots=False)
        t = time.perf_counter()
        recalculate(out / "stepgauge_II_MPE1.xlsx", "formulas")
        seconds = time.perf_counter() - t
    """,
}
TARGETS = {"build_stepgauge_m52": "< 1 s", "all_pairs_m3000": "< 1.5 s, < 600 MB",
           "recalc_libreoffice_m52": "—", "recalc_formulas_m52": "—"}

TAIL = """
import resource, json
print("RESULT", json.dumps({"seconds": seconds, "peak_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def run(name: str) -> dict:
    code = textwrap.dedent(CASES[name]) + TAIL
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    line = [l for l in p.stdout.splitlines() if l.startswith("RESULT")][-1]
    return json.loads(line[len("RESULT "):])


def main(names=None, repeats: int = 5) -> None:
    import os
    import statistics

    rows = ["| case | time / s best | time / s median | peak MB median | load at start | target |",
            "|---|---|---|---|---|---|"]
    for name in names or CASES:
        load = os.getloadavg()[0]
        runs = [run(name) for _ in range(repeats if "recalc" not in name else 2)]
        t = [r["seconds"] for r in runs]
        mem = statistics.median(r["peak_MB"] for r in runs)
        rows.append(f"| {name} | {min(t):.2f} | {statistics.median(t):.2f} | {mem:.0f} | {load:.1f} | {TARGETS[name]} |")
        print(rows[-1], flush=True)
    if names:
        return  # a partial run does not overwrite the recorded table
    out = ROOT / "bench" / "results" / "pointcloud.md"
    out.write_text("Measured by `python bench/bench_pointcloud.py` on the 2-core machine (each run in a fresh "
                   "process; peak memory = ru_maxrss; 'load at start' = 1-minute load average).\n\n"
                   + "\n".join(rows) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:] or None)
