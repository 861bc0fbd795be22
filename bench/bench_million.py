"""Scaling curves to a million points (issue 13).  Run: python bench/bench_million.py [part ...]

Parts (default: all):

* ``va``     per-factor V_A (Forbes 2022 V_A = G V_X G^T, all six factors of Forbes 2025) of a
             sphere and a cylinder fitted to m = 10^3 ... 10^6 points: the low-rank path
             (:mod:`xlfuncs.lowrank`, GP factors through a pivoted-Cholesky Nyström factor with a
             rigorous error bound) beside the exact blocked path (O(m^2), up to m = 50,000);
* ``verify`` the low-rank V_A against the exact one at m = 20,000 and 50,000, every factor:
             max |V_low - V_exact| / max |V_exact| and the stated bound;
* ``diagnose`` the mismatch locator on point records of a dense scan (four spheres, planted scale
             and probe-radius errors): dense path where it fits (memory need printed first), the
             structured path (:mod:`xlfuncs.locator.structured`) up to 200,000 records;
* ``pairs``  all-pairs distance uncertainties (eqs. 29-30) up to the m where the output itself
             (8 arrays of m(m-1)/2 doubles) is the limit: the memory need is printed before each
             run, and a run that would not fit in LIMIT_GB is skipped with the largest m that would.

Every measurement runs in a fresh subprocess (peak memory = its ru_maxrss, interpreter and
numpy included).  The machine has 2 cores shared with other jobs: the load average is printed
with every row, repeats give best and median.  Fitted exponents: least squares of log t on
log m over the points with m >= 10^4.  Results: bench/results/million_<tag>.md (and .json).
"""

from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT_GB = float(os.environ.get("BENCH_LIMIT_GB", "4"))
REPEATS = int(os.environ.get("BENCH_REPEATS", "2"))

SETUP = """
import time, resource, json
import numpy as np
from cmmwb.xlfuncs import pointcloud as pc, features as ft, blocked as bl
rng = np.random.default_rng(1)
m = {m}
element = "{element}"
params = pc.Parameters(0.2, 0.7, 0.7, 0.7, 0.2, 0.2, 200, 4.0, 400, 0.1, 0.1, 0.5)
probes = (pc.Probe("P1", (0, 0, -50.0)), pc.Probe("P2", (0, 40.0, -30.0), sigma_PQ_um=0.3))
if element == "sphere":
    z = rng.uniform(-0.3, 1, m); th = rng.uniform(0, 2 * np.pi, m)
    N = np.column_stack([np.sqrt(1 - z * z) * np.cos(th), np.sqrt(1 - z * z) * np.sin(th), z])
    X = np.array([200.0, 150.0, 50.0]) + 25.0 * N + rng.normal(scale=1e-3, size=(m, 3))
else:
    th = rng.uniform(0, 2 * np.pi, m); h = rng.uniform(-40, 40, m)
    N = np.column_stack([np.cos(th), np.sin(th), 0 * th])
    X = np.column_stack([200 + 20 * np.cos(th), 150 + 20 * np.sin(th), 50 + h]) + rng.normal(scale=1e-3, size=(m, 3))
cloud = pc.PointCloud(X, N, np.arange(m) % 2, probes)
t = time.perf_counter()
f = ft.fit(element, X, normals=N)
G = ft.G_A_X(f)
fit_s = time.perf_counter() - t
"""

VA = SETUP + """
t = time.perf_counter()
unc = bl.propagate_cloud(f, cloud, params, G=G, method="{method}")
seconds = time.perf_counter() - t
extra = {{"fit_s": fit_s}}
if unc.approximation is not None:
    a = unc.approximation.as_dict()
    extra["rank"] = a["rank"]; extra["bound_rel"] = a["relative_error_bound"]
"""

VERIFY = SETUP + """
t = time.perf_counter()
ex = bl.propagate_cloud(f, cloud, params, G=G)
exact_s = time.perf_counter() - t
t = time.perf_counter()
lo = bl.propagate_cloud(f, cloud, params, G=G, method="lowrank")
seconds = time.perf_counter() - t
err = {{k: float(np.max(np.abs(lo.V_local[k] - ex.V_local[k])) / np.max(np.abs(ex.V_local[k])))
        for k in pc.FACTORS}}
extra = {{"exact_s": exact_s, "rel_err": err, "bound_rel": lo.approximation.as_dict()["relative_error_bound"],
          "rank": lo.approximation.as_dict()["rank"]}}
"""

PAIRS = """
import time, resource, json
import numpy as np
from cmmwb.xlfuncs import pointcloud as pc
rng = np.random.default_rng(1)
m = {m}
X = rng.uniform(0, 800, (m, 3)); N = rng.normal(size=(m, 3)); N /= np.linalg.norm(N, axis=1)[:, None]
probes = (pc.Probe("P1", (0, 0, -50.0)), pc.Probe("P2", (0, 40.0, -30.0), sigma_PQ_um=0.3))
cloud = pc.PointCloud(X, N, np.arange(m) % 2, probes)
params = pc.Parameters(0.2, 0.7, 0.7, 0.7, 0.2, 0.2, 200, 4.0, 400, 0.1, 0.1, 0.5)
t = time.perf_counter()
r = pc.distance_components(cloud, params)
seconds = time.perf_counter() - t
assert r["u_um"].shape == (m * (m - 1) // 2,)
extra = {{}}
"""

TAIL = """
print("RESULT", json.dumps({"seconds": seconds, "peak_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, **extra}))
"""


def run(code: str) -> dict:
    env = dict(os.environ)
    p = subprocess.run([sys.executable, "-c", textwrap.dedent(code) + TAIL], cwd=ROOT,
                       capture_output=True, text=True, env=env)
    if p.returncode != 0:
        raise RuntimeError(p.stderr)
    line = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT")][-1]
    r = json.loads(line[len("RESULT "):])
    r["load"] = os.getloadavg()[0]
    return r


def exponent(ms, ts) -> float:
    pts = [(math.log(m), math.log(t)) for m, t in zip(ms, ts) if m >= 1e4 and t > 0]
    if len(pts) < 2:
        return float("nan")
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    return sum((x - mx) * (y - my) for x, y in pts) / sum((x - mx) ** 2 for x, _ in pts)


def pairs_bytes(m: int) -> float:
    """Output of the all-pairs distances: d, u and six components, doubles, plus the blocks."""
    return 8 * 8 * m * (m - 1) / 2 + 300e6


def largest_pairs_m(limit_bytes: float) -> int:
    m = int(math.sqrt(2 * (limit_bytes - 300e6) / 64))
    while pairs_bytes(m + 1) <= limit_bytes:
        m += 1
    return m


def repeat(code: str, n: int) -> dict:
    rs = [run(code) for _ in range(n)]
    t = [r["seconds"] for r in rs]
    out = dict(rs[0])
    out.update(best=min(t), median=statistics.median(t), peak_MB=max(r["peak_MB"] for r in rs),
               load=max(r["load"] for r in rs), repeats=n)
    return out


def part_va(res: dict, lines: list) -> None:
    lines += ["## Per-factor V_A, all six factors", "",
              "| element | method | m | time / s best | median | repeats | peak MB | load | rank ET, ER, P | stated relative bound (max over factors) |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for element in ("sphere", "cylinder"):
        for method, ms in (("lowrank", (1_000, 10_000, 100_000, 1_000_000)),
                           ("exact", (1_000, 10_000, 20_000, 50_000))):
            curve = []
            for m in ms:
                n = 1 if (method == "exact" and m >= 50_000) else REPEATS
                r = repeat(VA.format(m=m, element=element, method=method), n)
                curve.append((m, r["best"]))
                rank = ", ".join(str(r["rank"][k]) for k in ("ET", "ER", "P")) if "rank" in r else "exact"
                bound = f"{max(r['bound_rel'].values()):.1e}" if "bound_rel" in r else "0 (exact)"
                row = (f"| {element} | {method} | {m:,} | {r['best']:.2f} | {r['median']:.2f} | {n} | "
                       f"{r['peak_MB']:.0f} | {r['load']:.1f} | {rank} | {bound} |")
                print(row, flush=True)
                lines.append(row)
                res.setdefault("va", []).append({"element": element, "method": method, "m": m, **r})
            e = exponent(*zip(*curve))
            res.setdefault("exponents", {})[f"{element}_{method}"] = e
            lines.append(f"| {element} | {method} | fitted exponent t ~ m^k (m >= 10^4) | k = {e:.2f} | | | | | | |")
            print(lines[-1], flush=True)
    lines.append("")


def part_verify(res: dict, lines: list) -> None:
    lines += ["## Low-rank against exact, every factor", "",
              "| element | m | exact s | low-rank s | peak MB (both) | load | max rel. error R, PQ, S, ET, ER, P | stated bound ET, ER, P |",
              "|---|---|---|---|---|---|---|---|"]
    for element in ("sphere", "cylinder"):
        for m in (20_000, 50_000):
            r = run(VERIFY.format(m=m, element=element))
            errs = ", ".join(f"{r['rel_err'][k]:.1e}" for k in ("R", "PQ", "S", "ET", "ER", "P"))
            bnd = ", ".join(f"{r['bound_rel'][k]:.1e}" for k in ("ET", "ER", "P"))
            row = (f"| {element} | {m:,} | {r['exact_s']:.1f} | {r['seconds']:.1f} | {r['peak_MB']:.0f} | "
                   f"{r['load']:.1f} | {errs} | {bnd} |")
            print(row, flush=True)
            lines.append(row)
            res.setdefault("verify", []).append({"element": element, "m": m, **r})
    lines.append("")


def part_pairs(res: dict, lines: list) -> None:
    limit = LIMIT_GB * 2**30
    lines += ["## All-pairs distance uncertainties (eqs. 29-30, six components)", "",
              "| m | pairs | memory need / GB (estimate) | time / s best | median | peak MB | load |",
              "|---|---|---|---|---|---|---|"]
    curve = []
    for m in (1_000, 2_000, 4_000, 8_000, 16_000, 100_000):
        need = pairs_bytes(m)
        msg = f"all pairs, m = {m:,}: {m * (m - 1) // 2:,} distances need about {need / 2**30:.1f} GB"
        print(msg, flush=True)
        if need > limit:
            mmax = largest_pairs_m(limit)
            note = (f"| {m:,} | {m * (m - 1) // 2:,} | {need / 2**30:.1f} | not run: more than "
                    f"{LIMIT_GB:g} GB; the largest m that fits is {mmax:,} | | | |")
            print(note, flush=True)
            lines.append(note)
            continue
        r = repeat(PAIRS.format(m=m), REPEATS)
        curve.append((m, r["best"]))
        row = (f"| {m:,} | {m * (m - 1) // 2:,} | {need / 2**30:.2f} | {r['best']:.2f} | {r['median']:.2f} | "
               f"{r['peak_MB']:.0f} | {r['load']:.1f} |")
        print(row, flush=True)
        lines.append(row)
    curve_ms = [c for c in curve if c[0] >= 2000]
    e = exponent([c[0] * 5 for c in curve_ms], [c[1] for c in curve_ms])  # (x5: the fit uses m >= 10^4)
    res.setdefault("exponents", {})["all_pairs"] = e
    lines += [f"| fitted exponent t ~ m^k (m >= 2,000) | k = {e:.2f} | | | | | |", ""]


DIAG = """
import time, resource, json, sys
import numpy as np
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.locator import diagnose as dg, simulate as sm
from cmmwb.xlfuncs.model import MPE1  # Forbes 2025 Table 3
PAIR = (pc.Probe("P1", (0.0, 20.0, -30.0)), pc.Probe("P2", (0.0, -20.0, -30.0)))
n = {n}
rec = sm.simulate(sm.scan(PAIR, points=n), MPE1, {{"scale": 30.0, "probe_radius": 8.0}}, seed=3)
model = dg.Model(MPE1, PAIR, True)
t = time.perf_counter()
ds = dg.diagnose(rec, model, structured={structured})
seconds = time.perf_counter() - t
extra = {{"chosen": ds.chosen, "chi2_before": ds.chi2_before, "chi2_after": ds.chi2_after,
          "beta": [float(b) for b in ds.beta[-2:]], "u": [float(u) for u in np.sqrt(np.diag(ds.cov_beta))[-2:]]}}
if {structured}:
    extra["rank"] = ds.prep.C.ranks; extra["chi2_bound"] = ds.prep.C.chi2_bound()
"""


EQUAL = """
import time, resource, json
import numpy as np
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.locator import diagnose as dg, simulate as sm
from cmmwb.xlfuncs.model import MPE1  # Forbes 2025 Table 3
PAIR = (pc.Probe("P1", (0.0, 20.0, -30.0)), pc.Probe("P2", (0.0, -20.0, -30.0)))
rec = sm.simulate(sm.scan(PAIR, points={n}), MPE1, {{"scale": 30.0, "probe_radius": 8.0}}, seed=3)
model = dg.Model(MPE1, PAIR, True)
t = time.perf_counter()
s = dg.diagnose(rec, model, structured=True)
seconds = time.perf_counter() - t
t = time.perf_counter()
d = dg.diagnose(rec, model, structured=False)
dense_s = time.perf_counter() - t
def values(x):
    return {{"chi2_before": x.chi2_before, "chi2_after": x.chi2_after, "logp_before": x.logp_before,
            "logp": {{k: c.logp for k, c in x.candidates.items() if c.logp is not None}},
            "delta_chi2": {{k: c.delta_chi2 for k, c in x.candidates.items() if c.delta_chi2 is not None}},
            "labels": [" ".join(l) for l in x.sel_labels], "beta": [float(b) for b in x.beta],
            "u": [float(u) for u in np.sqrt(np.diag(x.cov_beta))]}}
def rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))
lr = [rel(s.candidates[k].delta_chi2, c.delta_chi2) for k, c in d.candidates.items() if c.delta_chi2 is not None]
extra = {{"chosen": [s.chosen, d.chosen], "chi2": max(rel(s.chi2_before, d.chi2_before), rel(s.chi2_after, d.chi2_after)),
          "logp": max(rel(s.logp_before, d.logp_before), max(rel(s.candidates[k].logp, c.logp) for k, c in d.candidates.items() if c.logp is not None)),
          "p": max([abs(s.logp_before - d.logp_before)] + [abs(s.candidates[k].logp - c.logp) for k, c in d.candidates.items() if c.logp is not None]),
          "lr": max(lr), "beta": rel(s.beta, d.beta), "u": rel(np.sqrt(np.diag(s.cov_beta)), np.sqrt(np.diag(d.cov_beta))),
          "u_obs": rel(s.u_obs, d.u_obs), "groups": max(rel(a["chi2"], b["chi2"]) for a, b in zip(sorted(s.groups, key=lambda g: (g["by"], g["group"])), sorted(d.groups, key=lambda g: (g["by"], g["group"])))),
          "dense_s": dense_s, "chi2_bound": s.prep.C.chi2_bound(), "structured": values(s), "dense": values(d)}}
extra["max"] = max(extra[k] for k in ("chi2", "p", "beta", "u", "u_obs", "groups"))
"""


def part_equal(res: dict, lines: list) -> None:
    """Structured against dense diagnose on the same records (issue 13: equal to relative 1e-8).
    BENCH_EQUAL_SIZES (default 2000,5000) sets the sizes; BENCH_EQUAL_FROM=million_equal.json
    re-renders the tables from stored results without running (the dense 5,000 takes minutes)."""
    stored = os.environ.get("BENCH_EQUAL_FROM")
    if stored:
        res["equal"] = json.loads(Path(stored).read_text())["equal"]
    else:
        for n in [int(v) for v in os.environ.get("BENCH_EQUAL_SIZES", "2000,5000").split(",")]:
            need = dense_diag_bytes(n)
            print(f"dense diagnose of {n:,} point records needs about {need / 2**30:.1f} GB", flush=True)
            res.setdefault("equal", []).append({"n": n, **run(EQUAL.format(n=n))})
    lines += ["## diagnose: structured against dense, same records", "",
              "Largest relative differences over all quantities of each kind.  p-values: the relative "
              "difference of p is the absolute difference of log p; it is given for p >= 1e-10 and for the "
              "p that differs most (all below 1e-10 are tiny p of strong effects, log p about -χ²/2, so an absolute "
              "rounding of χ² of a few 1e-8, relative 1e-12, shows as that relative difference of p).", "",
              "| records (observations) | chosen (structured / dense) | χ² | p-values p >= 1e-10 | p differing most: its log p, rel. diff of p | log p (relative) | candidate Δχ² | estimates | u (GLS) | u of records | group χ² | χ² rel. bound (structured) | time structured / dense s | peak MB | load |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in res["equal"]:
        s, d, n = r["structured"], r["dense"], r["n"]
        lp = [(s["logp"][k], d["logp"][k]) for k in d["logp"]] + [(s["logp_before"], d["logp_before"])]
        big = max(abs(a - b) for a, b in lp if b > math.log(1e-10))
        small = max(lp, key=lambda t: abs(t[0] - t[1]))
        row = (f"| {n:,} ({3 * n:,}) | {' + '.join(r['chosen'][0])} / {' + '.join(r['chosen'][1])} | {r['chi2']:.1e} | {big:.1e} | "
               f"{small[1]:.1f}, {abs(small[0] - small[1]):.1e} | "
               f"{r['logp']:.1e} | {r['lr']:.1e} | {r['beta']:.1e} | {r['u']:.1e} | {r['u_obs']:.1e} | {r['groups']:.1e} | "
               f"{r['chi2_bound']:.1e} | {r['seconds']:.1f} / {r['dense_s']:.1f} | {r['peak_MB']:.0f} | {r['load']:.1f} |")
        print(row, flush=True)
        lines.append(row)
    lines.append("")
    for r in res.get("equal", []):
        lines += [f"### {r['n']:,} records: the numbers of both paths", "",
                  "| quantity | structured | dense | rel. diff |", "|---|---|---|---|"]
        s, d = r["structured"], r["dense"]
        for k in ("chi2_before", "chi2_after", "logp_before"):
            lines.append(f"| {k} | {s[k]:.12g} | {d[k]:.12g} | {abs(s[k] - d[k]) / abs(d[k]):.1e} |")
        for k in d["logp"]:
            lines.append(f"| log p of {k} (Δχ² {d['delta_chi2'][k]:.6g}) | {s['logp'][k]:.12g} | {d['logp'][k]:.12g} | "
                         f"{abs(s['logp'][k] - d['logp'][k]) / abs(d['logp'][k]):.1e} |")
        for lab, bs, bd, us, ud in zip(d["labels"], s["beta"], d["beta"], s["u"], d["u"]):
            lines.append(f"| estimate {lab} | {bs:.12g} | {bd:.12g} | {abs(bs - bd) / max(abs(bd), 1e-300):.1e} |")
            lines.append(f"| u of {lab} | {us:.12g} | {ud:.12g} | {abs(us - ud) / ud:.1e} |")
        lines.append("")


def dense_diag_bytes(n_points: int, dims: int = 3) -> float:
    """The dense path holds the 3m x 3m V_X and its six factors' temporaries, C, its Cholesky
    factor and inverse, group blocks: about 9 (n dims)^2 doubles (measured: 2.46 GB peak at
    2,000 records, 6,000 observations)."""
    return 9 * 8.0 * (n_points * dims) ** 2


def part_diagnose(res: dict, lines: list) -> None:
    limit = LIMIT_GB * 2**30
    lines += ["## diagnose on point records (scan of four spheres, planted scale 30 ppm and probe radius 8 µm)", "",
              "| path | records | time / s | peak MB | load | chosen | estimates scale ppm, radius µm (u) | ranks ET, ER, P | chi2 rel. bound |",
              "|---|---|---|---|---|---|---|---|---|"]
    for structured, ns in ((False, (1_000, 2_000, 200_000)), (True, (1_000, 2_000, 20_000, 200_000))):
        curve = []
        for n in ns:
            if not structured:
                need = dense_diag_bytes(n)
                print(f"dense diagnose of {n:,} point records needs about {need / 2**30:.1f} GB", flush=True)
                if need > limit:
                    nmax = int(math.sqrt(limit / 72) / 3)
                    row = (f"| dense | {n:,} | not run: needs about {need / 2**30:.0f} GB, more than {LIMIT_GB:g} GB; "
                           f"the largest that fits is about {nmax:,} records | | | | | | |")
                    print(row, flush=True)
                    lines.append(row)
                    continue
            r = run(DIAG.format(n=n, structured=structured))
            curve.append((n, r["seconds"]))
            est = ", ".join(f"{b:.2f} ({u:.2f})" for b, u in zip(r["beta"], r["u"]))
            rank = ", ".join(str(v) for v in r["rank"].values()) if "rank" in r else "dense"
            bound = f"{r['chi2_bound']:.1e}" if "chi2_bound" in r else "exact"
            row = (f"| {'structured' if structured else 'dense'} | {n:,} | {r['seconds']:.1f} | {r['peak_MB']:.0f} | "
                   f"{r['load']:.1f} | {' + '.join(r['chosen'])} | {est} | {rank} | {bound} |")
            print(row, flush=True)
            lines.append(row)
            res.setdefault("diagnose", []).append({"structured": structured, "n": n, **r})
        if structured:
            e = exponent(*zip(*curve))
            lines.append(f"| structured | fitted exponent t ~ n^k (n >= 10^4) | k = {e:.2f} | | | | | | |")
    lines.append("")


def main(parts) -> None:
    res: dict = {}
    lines = [f"Measured by `python bench/bench_million.py {' '.join(parts)}` on the 2-core machine shared with "
             "other jobs (each measurement a fresh process; peak = ru_maxrss; load = 1-minute load "
             "average after the run, 2.0 = both cores busy).", ""]
    for p in parts:
        {"va": part_va, "verify": part_verify, "pairs": part_pairs, "diagnose": part_diagnose,
         "equal": part_equal}[p](res, lines)
    out = ROOT / "bench" / "results"
    tag = "_".join(parts)
    (out / f"million_{tag}.md").write_text("\n".join(lines) + "\n")
    (out / f"million_{tag}.json").write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:] or ["va", "verify", "pairs", "diagnose"])
