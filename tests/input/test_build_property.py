"""Property: whatever task file and points table `cmmwb build` is given, it either succeeds
(workbook + JSON, labels stored as text, never as formulas) or exits 2 with one clear line naming
the file, without a traceback and without writing anything."""

from __future__ import annotations

import csv
import json
import math
import shutil

import openpyxl
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cmmwb.generator.cli import main

PARAMS = ["sigma_R_um", "sigma_S_ppm", "sigma_Sa_ppm", "sigma_Q_ppm", "sigma_PQ_um", "sigma_ET_um",
          "lambda_ET_mm", "sigma_ER_urad", "lambda_ER_mm", "sigma_P0_um", "sigma_P_um", "lambda_P"]

# numbers a person (or a broken export) might put anywhere
odd_numbers = st.one_of(
    st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False),
    st.sampled_from([0.0, -0.0, 1e-300, 1e300, -1e300, math.nan, math.inf, -math.inf]),
    st.integers(min_value=-10**6, max_value=10**6),
)
odd_values = st.one_of(odd_numbers, st.booleans(), st.text(max_size=8),
                       st.sampled_from(["=1+1", "+A1", "-2", "@SUM(A1)", "0.2"]),
                       st.lists(st.floats(allow_nan=True), max_size=3))
labels = st.one_of(
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), min_size=0, max_size=8),
    st.sampled_from(["=SUM(A1)", "+1", "-2", "@x", "=cmd|' /C calc'!A0", "L1", "a,b", '"q"', "P1"]),
)


@st.composite
def tasks(draw):
    """A valid point-cloud task (odd but legal labels included) with zero to two defects."""
    m = draw(st.integers(min_value=2, max_value=5))
    probes = [{"id": f"P{k + 1}", "offset_mm": draw(st.lists(st.floats(-50, 50), min_size=3, max_size=3))}
              for k in range(draw(st.integers(min_value=1, max_value=2)))]
    params = {k: draw(st.floats(min_value=0, max_value=5)) for k in PARAMS}
    doc = {"task": {"kind": "pointcloud", "name": "t"}, "parameters": params, "probes": probes,
           "points": {"file": "pts.csv"}}
    if draw(st.booleans()):
        doc["mpe"] = {"A_um": draw(st.floats(0.1, 5)), "B_mm": draw(st.floats(10, 1000)), "K": 2}
    names = draw(st.lists(labels, min_size=m, max_size=m))
    rows = []
    for i in range(m):
        x = [draw(st.floats(-500, 500)) for _ in range(3)]
        n = draw(st.sampled_from([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]]))
        label = names[i] if draw(st.booleans()) else f"Q{i}"
        rows.append([label, *x, *n, draw(st.sampled_from([p["id"] for p in probes]))])
    header = ["id", "x", "y", "z", "nx", "ny", "nz", "probe"]
    for _ in range(draw(st.sampled_from([0, 0, 1, 1, 2]))):
        defect = draw(st.sampled_from(["param", "name", "kind", "drop", "extra", "coord", "normal", "probe",
                                       "distance", "header", "mpe", "offset"]))
        if defect == "param":
            params[draw(st.sampled_from(PARAMS))] = draw(odd_values)
        elif defect == "name":
            doc.setdefault("task", {})["name"] = draw(st.sampled_from(["", "../up", "a/b", ".hidden", "=x",
                                                                       "x" * 101]))
        elif defect == "kind":
            doc.setdefault("task", {})["kind"] = draw(st.sampled_from(["budget", "feature", "spline", ""]))
        elif defect == "drop":
            doc.pop(draw(st.sampled_from(["task", "points", "probes", "parameters"])), None)   # two drops may meet
        elif defect == "extra":
            doc[draw(st.sampled_from(["extra", "distance", "parameter"]))] = draw(odd_values)
        elif defect == "coord":
            rows[draw(st.integers(0, m - 1))][draw(st.integers(1, 3))] = draw(odd_values)
        elif defect == "normal":
            rows[draw(st.integers(0, m - 1))][4:7] = draw(st.lists(odd_numbers, min_size=3, max_size=3))
        elif defect == "probe":
            rows[draw(st.integers(0, m - 1))][7] = draw(st.sampled_from(["P9", "", "=P1"]))
        elif defect == "distance":
            doc["distances"] = [{"from": draw(st.sampled_from([r[0] for r in rows] + ["*", "nope"])),
                                 "to": draw(st.sampled_from([r[0] for r in rows] + ["*", 3]))}]
        elif defect == "header":
            header = draw(st.sampled_from([["id", "x", "y", "nx", "ny", "nz", "probe"], ["x", "y"], []]))
        elif defect == "mpe":
            doc["mpe"] = {"A_um": draw(odd_values), "B_mm": draw(odd_numbers)}
        else:
            probes[0]["offset_mm"] = draw(st.lists(odd_values, min_size=0, max_size=4))
    return doc, header, rows


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(case=tasks())
def test_build_succeeds_or_fails_cleanly(tmp_path_factory, case):
    doc, header, rows = case
    work = tmp_path_factory.mktemp("prop")
    task = work / "task.toml"
    try:
        task.write_text(tomli_w.dumps(doc), encoding="utf-8")
    except (TypeError, ValueError):
        task.write_text(str(doc), encoding="utf-8")          # not even TOML: must fail cleanly too
    with open(work / "pts.csv", "w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for r in rows:
            w.writerow([repr(v) if isinstance(v, float) else v for v in r])
    out = work / "out"
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["build", str(task), "--out", str(out), "--no-plots"])
    msg = err.getvalue().strip()
    assert code in (0, 2), msg
    if code == 2:
        assert len(msg.splitlines()) == 1 and msg.startswith("cmmwb: error: "), msg
        assert "Traceback" not in msg and ("task.toml" in msg or "pts.csv" in msg), msg
        assert not out.exists()
    else:
        name = doc["task"]["name"]
        book = out / f"{name}.xlsx"
        assert book.exists() and (out / f"{name}.json").exists()
        results = json.loads((out / f"{name}.json").read_text(encoding="utf-8"))
        assert all(math.isfinite(x) for x in _numbers(results)), "non-finite number in the JSON"
        wb = openpyxl.load_workbook(book)
        for ws, column in ((wb["Points"], 1), (wb["Results"], 1), (wb["Results"], 2)):
            for row in ws.iter_rows(min_row=2, min_col=column, max_col=column):
                for c in row:
                    if c.value is not None:
                        assert c.data_type == "s", (ws.title, c.coordinate, c.value)  # text, never a formula
    shutil.rmtree(work, ignore_errors=True)


def _numbers(obj):
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _numbers(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _numbers(v)
    elif isinstance(obj, float):
        yield obj
