"""``cmmwb calibrate`` on real CMM data: the SDSS plug-plate hole measurements of the public
repository csayres/fitPlugPlateMeas (University of Washington shop CMM, files ``D<plate>_<n>``:
measured and nominal hole centres in mm, 2-D).

The repository states no licence, so cmmwb does not ship the data: give the folder of a checkout
(``tests/testData`` of that repository).  Each D-file becomes point records (``x_nom, y_nom`` the
nominal hole centre, ``x, y`` the measured one, z = 0: 2-D data, one probe), the locator names the
systematic effects (the drilling machine's and the plate's, with the CMM's), and the REML fit
estimates the hyper-parameters the records identify.

Usage::

    python bench/plugplate_calibration.py /path/to/fitPlugPlateMeas/tests/testData

Writes ``bench/results/plugplate_calibration.md`` and the outputs of ``cmmwb calibrate`` into a
temporary folder.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cmmwb.generator.calibration.run import run_calibrate  # noqa: E402
from cmmwb.generator.diagnosis.run import load_model  # noqa: E402

#: starting values: a shop CMM of E = 3 + L/300 µm class (the records decide what they can)
TASK = """[parameters]
sigma_R_um = 5.0
sigma_S_ppm = 3.0
sigma_Sa_ppm = 3.0
sigma_Q_ppm = 3.0
sigma_PQ_um = 0.0
sigma_ET_um = 3.0
lambda_ET_mm = 200
sigma_ER_urad = 0.0
lambda_ER_mm = 0
sigma_P0_um = 0.0
sigma_P_um = 0.0
lambda_P = 0
"""


def convert(path: Path) -> str:
    """A D-file as point records (docs/recordings.md section 1b), 2-D."""
    rows = ["id,x_nom,y_nom,z_nom,x,y,z"]
    k = 0
    for line in path.read_text(errors="replace").splitlines():
        parts = line.split()
        if len(parts) != 9 or not re.match(r"^-?\d", parts[0]):
            continue
        mx, my, nx, ny = (float(p) for p in parts[:4])
        k += 1
        rows.append(f"H{k},{nx!r},{ny!r},0,{mx!r},{my!r},0")
    return "\n".join(rows) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", help="tests/testData of a fitPlugPlateMeas checkout")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "plugplate_calibration.md"))
    args = ap.parse_args(argv)
    files = sorted(p for p in Path(args.folder).iterdir() if re.match(r"^D\d+[A-Z]?_?\d*$", p.name))
    lines = ["# `cmmwb calibrate` on real CMM data: SDSS plug plates", "",
             f"Written by `bench/plugplate_calibration.py` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}) "
             "from the D-files of csayres/fitPlugPlateMeas `tests/testData` (not shipped: the repository states "
             "no licence). Each plate: hole centres measured against nominal (2-D point records, one probe); the "
             "effects the locator names are fixed effects; starting values a shop CMM (sigma_R 5 µm, S/Sa/Q "
             "3 ppm, ET 3 µm at 200 mm). Off (zero in the start, not estimated): sigma_PQ, sigma_ER/lambda_ER, "
             "sigma_P0, sigma_P/lambda_P: the D-files carry no probe offsets, probe ids or normals, so no probe "
             "factor is identifiable from them. What the plates measure is the hole position scatter: the "
             "drilling machine's and the plate's errors together with the CMM's, so sigma_R here is an upper "
             "bound of the CMM's repeatability.", ""]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "task.toml").write_text(TASK)
        model, label = load_model(str(tmp / "task.toml"), None)
        for f in files:
            csv = tmp / f"{f.name}.csv"
            csv.write_text(convert(f))
            t = time.perf_counter()
            result, _ = run_calibrate([csv], model, tmp / f"cal_{f.name}", task_path=tmp / "task.toml",
                                      task_label="shop CMM start values", workbook=False, profiles=False)
            dt = time.perf_counter() - t
            rec = result["records"][0]
            lines += [f"## {f.name}: {rec['records']} holes", "",
                      f"Effects named: {', '.join(sorted({e['name'] for e in result['effects']})) or 'none'}; "
                      f"chi2 (start values, as measured) {result['chi2']['before']:.1f} / {result['chi2']['dof_before']}; "
                      f"fit {dt:.1f} s.", "",
                      "| hyper-parameter | start | estimate | u | status | reason |", "|---|---|---|---|---|---|"]
            for h in result["hyper_parameters"]:
                if h["status"] == "off":
                    continue
                u = f"{h['u']:.3g}" if h["u"] is not None else ""
                lines.append(f"| {h['name']} | {h['start']:g} | {h['estimate']:.4g} | {u} | {h['status']} | "
                             f"{h['reason'].replace('|', '/')} |")
            lines.append("")
            print(f.name, json.dumps({h["name"]: [h["estimate"], h["u"], h["status"]] for h in result["hyper_parameters"]
                                      if h["status"] != "off"}))
    Path(args.out).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
