"""All-pairs distance uncertainties at m = 3,000 (4,498,500 distances, six components, two probes;
Forbes 2025 eqs. 29-30) against the dense numpy reference, in one run (issue 26).

Cases, each in a fresh subprocess (peak = its ru_maxrss, interpreter and numpy included), run
alternately so that each sees the same load:

* ``streamed``  :func:`xlfuncs.pointcloud.iter_distance_components`: blocks of 16,384 pairs in
                float64, each written to eight raw float64 files (all 8 m(m-1)/2 numbers kept,
                on disk) -- memory a few blocks (goal <= 300 MB); the default threads (now one);
* ``streamed, 2 threads``  the same with ``workers=2`` (the thread policy: is the second core
                worth its GIL hand-offs?);
* ``arrays``    :func:`xlfuncs.pointcloud.distance_components`: the eight arrays in memory
                (288 MB of output by themselves); the default threads (now one);
* ``dense``     the reference: V_X formed densely (:func:`xlfuncs.pointcloud.V_X`, 3m x 3m) and
                u(d_ij)^2 = n^T (V_ii + V_jj - V_ij - V_ji) n for every pair with numpy, row by row.

``--before=DIR:LABEL`` adds the streamed and in-memory cases on another checkout's ``xlfuncs`` (the
code before, ``mkdir -p DIR/cmmwb && git archive COMMIT xlfuncs | tar -x -C DIR/cmmwb``: the
package must be ``DIR/cmmwb/xlfuncs``, or the editable install's ``cmmwb.xlfuncs`` is imported
instead; every run checks which file it imported), alternating with the others in the same run.
The 2-core machine is shared with other jobs: every row gives the 1-minute load average; the
speed-up is the ratio of the dense reference's best (and median) wall time to the case's in the
same run, and of the median CPU times (all threads), the measure least disturbed by the load.
Results: bench/results/pairs.md.
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
#: the line of bench/results/pairs.md from which on the text is kept when the table is rewritten
NOTES = "<!-- notes: not written by bench_pairs.py -->"

SETUP = """
import time, resource, json, os, tempfile
import numpy as np
from cmmwb.xlfuncs import pointcloud as pc
rng = np.random.default_rng(1)
m = 3000
X = rng.uniform(0, 800, (m, 3)); N = rng.normal(size=(m, 3)); N /= np.linalg.norm(N, axis=1)[:, None]
probes = (pc.Probe("P1", (0, 0, -50.0)), pc.Probe("P2", (0, 40.0, -30.0), sigma_PQ_um=0.3))
cloud = pc.PointCloud(X, N, np.arange(m) % 2, probes)
params = pc.Parameters(0.2, 0.7, 0.7, 0.7, 0.2, 0.2, 200, 4.0, 400, 0.1, 0.1, 0.5)
"""

STREAMED = """
tmp = tempfile.mkdtemp()
t = time.perf_counter(); c = time.process_time()
files = None
count = 0
for sl, part in pc.iter_distance_components(cloud, params, workers=WORKERS):
    if files is None:
        files = {k: open(os.path.join(tmp, k + ".f64"), "wb") for k in part}
    for k, v in part.items():
        v.tofile(files[k])
    count += sl.stop - sl.start
for f in files.values():
    f.close()
seconds = time.perf_counter() - t; cpu = time.process_time() - c
assert count == m * (m - 1) // 2 and os.path.getsize(os.path.join(tmp, "u_um.f64")) == 8 * count
u = np.fromfile(os.path.join(tmp, "u_um.f64"))
check = [float(u[0]), float(u[count // 2]), float(u[-1])]
for k in files:
    os.remove(os.path.join(tmp, k + ".f64"))
os.rmdir(tmp)
"""

CASES = {
    "streamed": SETUP + "WORKERS = None" + STREAMED,          # the default of the code measured
    "streamed, 2 threads": SETUP + "WORKERS = 2" + STREAMED,
    "arrays": SETUP + """
t = time.perf_counter(); c = time.process_time()
r = pc.distance_components(cloud, params)
seconds = time.perf_counter() - t; cpu = time.process_time() - c
u = r["u_um"]
check = [float(u[0]), float(u[len(u) // 2]), float(u[-1])]
""",
    "dense": SETUP + """
t = time.perf_counter(); c = time.process_time()
V = pc.V_X(cloud, params)
V4 = V.reshape(m, 3, m, 3)
Vd = np.einsum("iaib->iab", V4)
u = np.empty(m * (m - 1) // 2)
pos = 0
for i in range(m - 1):
    dx = X[i + 1:] - X[i]
    n = dx / np.linalg.norm(dx, axis=1)[:, None]
    var = (np.einsum("ja,ab,jb->j", n, Vd[i], n) + np.einsum("ja,jab,jb->j", n, Vd[i + 1:], n)
           - 2.0 * np.einsum("aj,jab,jb->j", n.T, V4[i, :, i + 1:, :].transpose(1, 0, 2), n))
    u[pos:pos + var.size] = np.sqrt(var)
    pos += var.size
seconds = time.perf_counter() - t; cpu = time.process_time() - c
check = [float(u[0]), float(u[len(u) // 2]), float(u[-1])]
""",
}

TAIL = """
print("RESULT", json.dumps({"seconds": seconds, "cpu": cpu, "module": pc.__file__,
                            "peak_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                            "check": check}))
"""


def run(case: str, source: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(source))
    p = subprocess.run([sys.executable, "-c", textwrap.dedent(CASES[case]) + TAIL], cwd=source,
                       capture_output=True, text=True, env=env)
    if p.returncode != 0:
        raise RuntimeError(p.stderr)
    r = json.loads([ln for ln in p.stdout.splitlines() if ln.startswith("RESULT")][-1][7:])
    # the editable install maps cmmwb.xlfuncs to this checkout unless DIR/cmmwb/xlfuncs exists
    assert Path(r["module"]).resolve().is_relative_to(source.resolve()), (source, r["module"])
    r["load"] = os.getloadavg()[0]
    return r


def main(argv: list[str]) -> int:
    repeats = int(os.environ.get("BENCH_REPEATS", "3"))
    runs = [("streamed", ROOT, "this checkout"), ("streamed, 2 threads", ROOT, "this checkout"),
            ("arrays", ROOT, "this checkout")]
    for a in argv:
        if a.startswith("--before="):       # a checkout of the code before, e.g. git archive COMMIT xlfuncs
            src, _, label = a.split("=", 1)[1].partition(":")
            runs[0:0] = [("streamed", Path(src).resolve(), label or src),
                         ("arrays", Path(src).resolve(), label or src)]
    runs.append(("dense", ROOT, "reference"))
    res: dict[tuple, list[dict]] = {(c, lab): [] for c, _s, lab in runs}
    for _ in range(repeats):
        for c, src, lab in runs:
            res[(c, lab)].append(run(c, src))
            print(lab, c, res[(c, lab)][-1], flush=True)
    ref = res[("dense", "reference")][0]["check"]
    for key, rs in res.items():
        for r in rs:
            assert max(abs(a - b) / b for a, b in zip(r["check"], ref)) < 1e-12, (key, r["check"], ref)
    best_dense = min(r["seconds"] for r in res[("dense", "reference")])
    median_dense = statistics.median(r["seconds"] for r in res[("dense", "reference")])
    cpu_dense = statistics.median(r["cpu"] for r in res[("dense", "reference")])
    lines = [
        "Measured by `python bench/bench_pairs.py` on the 2-core machine shared with other jobs (each row "
        "a fresh process; the cases of one run alternate, so each sees the same load; peak = ru_maxrss; "
        "load = highest 1-minute load average after its runs, 2.0 = both cores busy; CPU = process time of "
        "all its threads, which the other jobs' load disturbs far less than the wall time).  m = 3,000: "
        "4,498,500 distances, eight float64 outputs each (288 MB if held); every case's u equals the "
        "dense reference's to 1e-12.", "",
        "| code | case | time / s best | median | peak MB best | speed-up vs dense (best / best, same run) "
        "| speed-up (median / median) | CPU s median (all threads) | CPU speed-up (median / median) | load |",
        "|---|---|---|---|---|---|---|---|---|---|"]
    for (c, lab), rs in res.items():
        ts = [r["seconds"] for r in rs]
        cs = [r["cpu"] for r in rs]
        lines.append(f"| {lab} | {c} | {min(ts):.2f} | {statistics.median(ts):.2f} | "
                     f"{min(r['peak_MB'] for r in rs):.0f} | {best_dense / min(ts):.1f}x | "
                     f"{median_dense / statistics.median(ts):.1f}x | "
                     f"{statistics.median(cs):.2f} | {cpu_dense / statistics.median(cs):.1f}x | "
                     f"{max(r['load'] for r in rs):.1f} |")
    out = ROOT / "bench" / "results" / "pairs.md"
    old = out.read_text(encoding="utf-8") if out.exists() else ""
    notes = old[old.index(NOTES):] if NOTES in old else NOTES + "\n"   # the hand-written profile
    out.write_text("\n".join(lines) + "\n\n" + notes, encoding="utf-8")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
