"""One benchmark case in a fresh Python process: its peak memory (ru_maxrss) and CPU time are the
case's own, with one BLAS thread.  The case's code builds a dict ``out``; :func:`run_fresh`
appends the resource figures, reads the printed ``RESULT`` line back and adds the 1-minute load
average after the run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

TAIL = """
import json, resource
ru = resource.getrusage(resource.RUSAGE_SELF)
out["peak_MB"] = ru.ru_maxrss / 1024
out["cpu_s"] = ru.ru_utime + ru.ru_stime
print("RESULT", json.dumps(out))
"""


def run_fresh(code: str) -> dict:
    """``code`` (which sets ``out``) in a fresh process of this Python, one BLAS thread."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    p = subprocess.run([sys.executable, "-c", textwrap.dedent(code) + TAIL], cwd=ROOT, capture_output=True,
                       text=True, env=env)
    if p.returncode != 0:
        raise RuntimeError(p.stderr)
    r = json.loads([ln for ln in p.stdout.splitlines() if ln.startswith("RESULT")][-1][7:])
    r["load"] = os.getloadavg()[0]
    return r
