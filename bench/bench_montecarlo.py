"""Direct method (law of propagation, Forbes 2025 eqs. 28-30 / section 5.6) against a JCGM 101
Monte Carlo of the same model (xlfuncs.montecarlo: every influence factor drawn, the GP factors as
Gaussian-process draws, the measurand evaluated exactly per draw).  Run:
python bench/bench_montecarlo.py [case ...]

Cases: the step gauge of Forbes 2025 Table 5 / Figure 7 (scenario II, MPE1 parameters, all 101
distances), a sphere and a cylinder fitted to 300 points.  For each: the direct u and its time
(best of many repeats), the Monte Carlo u with the number of draws the adaptive procedure of
JCGM 101 7.9 needs for two significant digits (batches of 10^4), its time, the largest deviation
|u_MC / u_direct - 1| and the speed ratio t_MC / t_direct.  REPEATS runs per case with different
seeds (best and median; the machine has 2 cores shared with other jobs).  Results go to
bench/results/montecarlo.md.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cmmwb.generator.pointcloud import job  # noqa: E402
from cmmwb.generator.taskfile import read_toml  # noqa: E402
from cmmwb.xlfuncs import blocked as bl  # noqa: E402
from cmmwb.xlfuncs import features as ft  # noqa: E402
from cmmwb.xlfuncs import montecarlo as mc  # noqa: E402
from cmmwb.xlfuncs import pointcloud as pc  # noqa: E402

REPEATS = int(os.environ.get("BENCH_REPEATS", "3"))
N_DIG = 2
BATCH = 10_000
PARAMS = pc.Parameters(0.2, 0.7, 0.7, 0.7, 0.2, 0.2, 200, 4.0, 400, 0.1, 0.1, 0.5)
PROBES = (pc.Probe("P1", (0, 0, -50.0)), pc.Probe("P2", (0, 40.0, -30.0), sigma_PQ_um=0.3))


def timed(fn, min_seconds: float = 0.5):
    """Best time of fn() over repeats lasting at least ``min_seconds`` in all."""
    best, total, out = float("inf"), 0.0, None
    while total < min_seconds or best == float("inf"):
        t = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t
        best, total = min(best, dt), total + dt
    return best, out


def stepgauge():
    path = ROOT / "generator" / "examples" / "stepgauge_II_MPE1.toml"
    task = job.load(path, read_toml(path))
    t_direct, d = timed(lambda: pc.distance_components(task.cloud, task.params, task.pairs))

    def run(seed):
        t = time.perf_counter()
        r = mc.distances(task.cloud, task.params, task.pairs, n_dig=N_DIG, batch=BATCH,
                         rng=np.random.default_rng(seed))
        return r, time.perf_counter() - t
    return "step gauge, scenario II MPE1 (m = 52, 101 distances)", d["u_um"], t_direct, run, "µm"


def _feature(element: str, m: int = 300):
    rng = np.random.default_rng(1)
    if element == "sphere":
        z = rng.uniform(-0.3, 1, m)
        th = rng.uniform(0, 2 * np.pi, m)
        N = np.column_stack([np.sqrt(1 - z * z) * np.cos(th), np.sqrt(1 - z * z) * np.sin(th), z])
        X = np.array([200.0, 150.0, 50.0]) + 25.0 * N + rng.normal(scale=1e-3, size=(m, 3))
    else:
        th, h = rng.uniform(0, 2 * np.pi, m), rng.uniform(-40, 40, m)
        N = np.column_stack([np.cos(th), np.sin(th), 0 * th])
        X = np.column_stack([200 + 20 * np.cos(th), 150 + 20 * np.sin(th), 50 + h]) + \
            rng.normal(scale=1e-3, size=(m, 3))
    cloud = pc.PointCloud(X, N, np.arange(m) % 2, PROBES)

    def direct():
        f = ft.fit(element, X, normals=N)
        return f, bl.propagate_cloud(f, cloud, PARAMS)
    t_direct, (f, unc) = timed(direct)

    def run(seed):
        t = time.perf_counter()
        r = mc.feature(f, cloud, PARAMS, n_dig=N_DIG, batch=BATCH, rng=np.random.default_rng(seed))
        return r, time.perf_counter() - t
    return (f"{element} fitted to {m} points, local parameters {', '.join(f.local_names)}",
            unc.u_local(), t_direct, run, "mm, rad")


CASES = {"stepgauge": stepgauge, "sphere_m300": lambda: _feature("sphere"),
         "cylinder_m300": lambda: _feature("cylinder")}


def main(names=None) -> None:
    rows = ["| case | direct time / s (best) | MC draws (best / median) | MC time / s (best / median) | "
            "max abs(u_MC/u_direct - 1) (median run) | speed ratio t_MC/t_direct (median) | converged |",
            "|---|---|---|---|---|---|---|"]
    details = []
    for name in names or CASES:
        load = os.getloadavg()[0]
        title, u_direct, t_direct, run, unit = CASES[name]()
        runs = [run(seed) for seed in range(1, REPEATS + 1)]
        draws = [r.draws for r, _ in runs]
        times = [t for _, t in runs]
        dev = [float(np.max(np.abs(r.u[u_direct > 0] / u_direct[u_direct > 0] - 1))) for r, _ in runs]
        med = sorted(range(REPEATS), key=lambda k: times[k])[REPEATS // 2]
        rows.append(f"| {name} | {t_direct:.4f} | {min(draws)} / {statistics.median(draws):.0f} | "
                    f"{min(times):.1f} / {statistics.median(times):.1f} | {dev[med]:.4f} | "
                    f"{statistics.median(times) / t_direct:.0f} | {all(r.converged for r, _ in runs)} |")
        print(rows[-1], flush=True)
        r = runs[med][0]
        lines = [f"### {name}: {title}", "", f"load average at start {load:.1f}; median run: {r.draws} draws "
                 f"in {runs[med][1]:.1f} s", "", f"| output | u direct ({unit}) | u Monte Carlo | 2 s_u | "
                 "tolerance delta (2 digits) |", "|---|---|---|---|---|"]
        show = range(len(r.names)) if len(r.names) <= 12 else list(range(0, len(r.names), 10))
        for k in show:
            lines.append(f"| {r.names[k]} | {u_direct[k]:.6g} | {r.u[k]:.6g} | {2 * r.s_u[k]:.2g} | "
                         f"{r.tolerance[k]:.2g} |")
        details += lines + [""]
    out = ROOT / "bench" / "results" / "montecarlo.md"
    out.write_text(
        "Measured by `python bench/bench_montecarlo.py` on the 2-core machine shared with other jobs "
        f"({REPEATS} Monte Carlo runs per case with different seeds).  Monte Carlo: JCGM 101 section 7.9, "
        f"batches of {BATCH} draws until 2 s_u <= delta for {N_DIG} significant digits of every output's u.  "
        "The step-gauge Monte Carlo also draws each factor alone (the six components of eq. 30), as the "
        "direct method gives them; the feature Monte Carlo refits the element to every draw (Gauss-Newton).\n\n"
        + "\n".join(rows) + "\n\n" + "\n".join(details))


if __name__ == "__main__":
    main(sys.argv[1:] or None)
