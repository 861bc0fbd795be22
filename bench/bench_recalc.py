"""`cmmwb recalc` in each engine, as a user runs it.  Run: python bench/bench_recalc.py [--runs N] [--engines ...]

Builds the steering knuckle (budget) and the m = 52 step gauge II/MPE1 (point cloud), then times
the command `cmmwb recalc BOOK` in a fresh process: with the default engine (the fastest
installed: Gnumeric here) and with `--engine gnumeric`, `libreoffice`, `formulas`.  Target: the
default engine under 5 s on both books.  Wall time is the best of the runs; CPU is the command's
and its children's (ssconvert, soffice) user + system time in that run; the 1-minute load
average before each case is recorded, since the machine is shared.  Written to
bench/results/recalc.md.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "generator" / "examples"
BOOKS = {"knuckle (budget)": "knuckle", "step gauge II, MPE1, m = 52 (pointcloud)": "stepgauge_II_MPE1"}
ENGINES = (None, "gnumeric", "libreoffice", "formulas")
CMMWB = [sys.executable, "-m", "cmmwb.generator"]


def run(args: list[str]) -> tuple[float, float, str]:
    """Wall and CPU seconds of one command (children included), and its stderr."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run(args, capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise RuntimeError(p.stderr)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, p.stderr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--engines", nargs="+", default=["default", *ENGINES[1:]],
                    help="default (no --engine), gnumeric, libreoffice, formulas")
    args = ap.parse_args()
    runs = args.runs
    engines = [None if e == "default" else e for e in args.engines]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, name in BOOKS.items():
            out = Path(tmp) / name
            subprocess.run([*CMMWB, "build", str(EXAMPLES / f"{name}.toml"), "--out", str(out), "--no-plots"],
                           check=True, capture_output=True)
            book = out / f"{name}.xlsx"
            for engine in engines:
                command = [*CMMWB, "recalc", str(book)] + (["--engine", engine] if engine else [])
                load = os.getloadavg()[0]
                best = None
                for _ in range(runs):
                    wall, cpu, err = run(command)
                    if best is None or wall < best[0]:
                        best = (wall, cpu)
                said = engine or err.split("engine ", 1)[1].split(" ", 1)[0] + " (default)"
                rows.append((label, said, best[0], best[1], load))
                print(f"{label:42s} {said:22s} {best[0]:6.2f} s wall {best[1]:6.2f} s CPU  load {load:.1f}",
                      flush=True)
    lines = ["# `cmmwb recalc` per engine", "",
             f"`python bench/bench_recalc.py --runs {runs} --engines {' '.join(args.engines)}` (best wall time of the runs; CPU of that run, children "
             "included; 1-minute load average before the case). Target: the default engine under 5 s.", "",
             "| book | engine | wall s | CPU s | load |", "|---|---|---:|---:|---:|"]
    lines += [f"| {b} | {e} | {w:.2f} | {c:.2f} | {ld:.1f} |" for b, e, w, c, ld in rows]
    (ROOT / "bench" / "results" / "recalc.md").write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
