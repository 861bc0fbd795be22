"""Recordings (docs/recordings.md section 1): what is read, and bad input that gets one
clear message naming the file, line and column, exit status 2 and nothing in the output folder."""


import numpy as np
import pytest

from cmmwb.xlfuncs.locator.recordings import (
    LengthRecords,
    PointRecords,
    RecordingsError,
    parse_recordings,
)

from tests.helpers import run_cmmwb as run

LENGTHS = """# an ISO 10360-2 style test, two records
# second comment line
id,x1,y1,z1,x2,y2,z2,reference_mm,measured_mm,n1x,n1y,n1z,n2x,n2y,n2z,probe1,probe2,temperature_C,time_s,group,operator
R1,100,200,300,200,200,300,100.0,100.0003,-1,0,0,1,0,0,P1,P1,20.1,0,X,ann
R2,100,200,300,100,400,300,200.0,199.9998,0,-1,0,0,1,0,P1,P2,20.3,60,Y,bob
R3,100,200,300,100,200,600,300.0,300.0011,0,0,-1,0,0,1.0005,P2,P2,20.2,120,Z,ann
"""

POINTS = """id,x_nom,y_nom,z_nom,x,y,z,px,py,pz,probe
B1,0,0,0,500.0002,400.0001,150,0,0,-50,P1
B2,100,0,0,600.0001,399.9999,150,0,0,-50,P1
B3,0,100,0,500.0000,500.0003,150,0,0,-50,P1
"""


def test_length_records_with_every_optional_column():
    rec = parse_recordings(LENGTHS)
    assert isinstance(rec, LengthRecords) and rec.n == 3
    assert rec.lines == (4, 5, 6)                          # comments count as lines
    assert np.allclose(rec.residual_um, [0.3, -0.2, 1.1])
    assert rec.probe1 == ("P1", "P1", "P2") and rec.group == ("X", "Y", "Z")
    assert np.allclose(np.linalg.norm(rec.N2, axis=1), 1.0)   # normals within 1e-3 are normalized
    assert rec.extra == {"operator": ["ann", "bob", "ann"]}  # unknown columns are kept
    assert rec.comments[0].startswith("an ISO 10360-2")


def test_point_records_and_two_dimensional_data():
    rec = parse_recordings(POINTS)
    assert isinstance(rec, PointRecords) and rec.n == 3 and rec.planar
    assert rec.P_mm.shape == (3, 3) and rec.probe == ("P1",) * 3


def _lines(text, row, col, value):
    lines = text.splitlines()
    f = lines[row].split(",")
    f[col] = value
    lines[row] = ",".join(f)
    return "\n".join(lines) + "\n"


BAD = {
    # name: (text, words that the message must contain)
    "missing column": (LENGTHS.replace(",x2,", ",xx2,"), ["missing column 'x2'", "line 3"]),
    "text in a number cell": (_lines(LENGTHS, 4, 8, "abc"), ["line 5", "'measured_mm'", "'abc' is not a number"]),
    "NaN": (_lines(LENGTHS, 3, 1, "nan"), ["line 4", "'x1'", "not a finite number"]),
    "empty cell": (_lines(LENGTHS, 5, 18, ""), ["line 6", "'time_s'", "not a number"]),
    "duplicate id": (_lines(LENGTHS, 5, 0, "R1"), ["line 6", "'id'", "also on line 4"]),
    "normal not unit": (_lines(LENGTHS, 4, 9, "-0.9"), ["line 5", "'n1x'", "not a unit vector"]),
    "half the normals": (LENGTHS.replace(",n2z,", ",n2zz,"), ["missing column 'n2z'", "normals"]),
    "one length record": ("\n".join(LENGTHS.splitlines()[:4]) + "\n", ["fewer records than parameters"]),
    "two 3-D point records": ("\n".join(POINTS.replace("399.9999,150", "399.9999,151").splitlines()[:3]) + "\n",
                              ["2 point records give 6 coordinates", "fewer records than parameters"]),
    "both kinds": (LENGTHS.replace(",group,", ",x_nom,"), ["both measured_mm", "one kind"]),
    "neither kind": (POINTS.replace("x_nom", "xnom"), ["neither measured_mm", "x_nom"]),
    "coincident ends": (_lines(LENGTHS, 3, 4, "100"), ["line 4", "coincide"]),
    "wrong field count": (LENGTHS.replace("X,ann", "X"), ["line 4", "fields"]),
    "probe with two offsets": (POINTS.replace("150,0,0,-50,P1\nB3", "150,0,0,-60,P1\nB3"),
                               ["line 3", "'px'", "probe 'P1' has offset", "one probe id, one offset"]),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_recordings_name_the_line_and_column(case):
    text, words = BAD[case]
    with pytest.raises(RecordingsError) as err:
        parse_recordings(text)
    msg = str(err.value)
    for w in words:
        assert w in msg, f"{case}: {w!r} not in {msg!r}"


TASK = """[parameters]
sigma_R_um = 0.3
[[probes]]
id = "P1"
offset_mm = [0.0, 0.0, -50.0]
[[probes]]
id = "P2"
offset_mm = [0.0, 0.0, -80.0]
"""


CLI_BAD = {
    "text in a number cell": (_lines(LENGTHS, 4, 8, "abc"), TASK, ["rec.csv", "line 5", "'measured_mm'"]),
    "unknown probe": (LENGTHS.replace("P2,P2", "P9,P9"), TASK, ["rec.csv", "line 6", "unknown probe 'P9'"]),
    "all sigmas zero": (LENGTHS, "[parameters]\nsigma_R_um = 0\n", ["task.toml", "[parameters]", "zero"]),
    "typo in the task": (LENGTHS, TASK.replace("sigma_R_um", "sigma_RR_um"), ["task.toml", "sigma_RR_um", "unknown key"]),
}


@pytest.mark.parametrize("case", list(CLI_BAD))
def test_diagnose_exits_2_and_writes_nothing(tmp_path, case):
    csv, task, words = CLI_BAD[case]
    (tmp_path / "rec.csv").write_text(csv)
    (tmp_path / "task.toml").write_text(task)
    out = tmp_path / "out"
    p = run("diagnose", "rec.csv", "--task", "task.toml", "--out", "out", cwd=tmp_path)
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr and p.stderr.count("\n") == 1
    for w in words:
        assert w in p.stderr, f"{w!r} not in {p.stderr!r}"
    assert not out.exists() or not any(out.iterdir())


def test_diagnose_needs_exactly_one_simulation(tmp_path):
    (tmp_path / "rec.csv").write_text(LENGTHS)
    (tmp_path / "task.toml").write_text(TASK)
    both = run("diagnose", "rec.csv", "--task", "task.toml", "--sigma-um", "0.3", "--out", "o", cwd=tmp_path)
    none = run("diagnose", "rec.csv", "--out", "o", cwd=tmp_path)
    assert both.returncode == none.returncode == 2
    assert "not both" in both.stderr and "--sigma-um" in none.stderr
    assert not (tmp_path / "o").exists()


def test_a_label_that_looks_like_a_formula_stays_text(tmp_path):
    import openpyxl

    (tmp_path / "rec.csv").write_text(LENGTHS.replace("R2,", "=SUM(A1),").replace(",X,", ",=1+1,"))
    p = run("diagnose", "rec.csv", "--sigma-um", "0.3", "--out", "out", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    ws = openpyxl.load_workbook(tmp_path / "out" / "diagnosis.xlsx")["Records"]
    values = [c.value for c in ws["A"]]
    assert "=SUM(A1)" in values and ws["A3"].data_type == "s"
