"""Bad input: exit status 2, one message naming the file and line or key, no traceback, and an
output folder that holds nothing from the failed run."""

from pathlib import Path

import pytest

from tests.helpers import run_cmmwb as run
from tests.helpers.tasks import write_random_task


def break_file(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))


CASES = {
    # name: (which file, old, new, words the message must contain)
    "malformed toml": ("toml", 'kind = "pointcloud"', 'kind = "pointcloud', ["malformed TOML", "line"]),
    "non-numeric parameter": ("toml", "sigma_R_um = 0.2", 'sigma_R_um = "abc"', ["[parameters] sigma_R_um", "number"]),
    "negative sigma": ("toml", "sigma_R_um = 0.2", "sigma_R_um = -0.2", ["[parameters] sigma_R_um", ">= 0"]),
    "nan parameter": ("toml", "sigma_R_um = 0.2", "sigma_R_um = nan", ["[parameters] sigma_R_um", "finite"]),
    "typo in a key": ("toml", "sigma_R_um = 0.2", "sigma_RR_um = 0.2", ["[parameters] sigma_RR_um", "unknown key"]),
    "missing column": ("csv", "id,x,y,z,nx,ny,nz,probe", "id,x,y,nx,ny,nz,probe", ["missing column 'z'", "line 1"]),
    "unknown probe": ("csv", ",P1\n", ",P9\n", ["line 2", "unknown probe 'P9'"]),
}
FIELD_CASES = {
    # name: (data row, column, new text, words)
    "text in a number cell": (3, 1, "abc", ["line 4", "'x'", "'abc' is not a number"]),
    "NaN coordinate": (2, 2, "nan", ["line 3", "'y'", "not a finite number"]),
    "infinite coordinate": (1, 3, "inf", ["line 2", "'z'", "not a finite number"]),
    "empty cell": (2, 4, "", ["line 3", "'nx'", "not a number"]),
}


def set_field(csv: Path, row: int, column: int, value: str) -> None:
    lines = csv.read_text().splitlines()
    f = lines[row].split(",")
    f[column] = value
    lines[row] = ",".join(f)
    csv.write_text("\n".join(lines) + "\n")


@pytest.fixture
def task(tmp_path):
    return write_random_task(tmp_path, 11, m=5, probes=2, name="t")


@pytest.mark.parametrize("case", list(CASES) + list(FIELD_CASES))
def test_bad_input_exits_2_with_one_clear_message(tmp_path, task, case):
    if case in CASES:
        which, old, new, words = CASES[case]
        break_file(task if which == "toml" else task.with_suffix(".csv"), old, new)
    else:
        row, column, new, words = FIELD_CASES[case]
        set_field(task.with_suffix(".csv"), row, column, new)
    out = tmp_path / "out"
    r = run("build", str(task), "--out", str(out))
    assert r.returncode == 2, r.stderr
    msg = r.stderr.strip()
    assert "Traceback" not in msg and len(msg.splitlines()) == 1, msg
    assert ("t.toml" in msg) or ("t.csv" in msg)
    for w in words:
        assert w in msg, msg
    assert not out.exists()


def test_non_unit_normal_is_named(tmp_path, task):
    csv = task.with_suffix(".csv")
    lines = csv.read_text().splitlines()
    f = lines[3].split(",")
    f[4:7] = ["1", "1", "0"]
    lines[3] = ",".join(f)
    csv.write_text("\n".join(lines) + "\n")
    r = run("build", str(task), "--out", str(tmp_path / "out"))
    assert r.returncode == 2 and "line 4" in r.stderr and "not a unit vector" in r.stderr


def test_two_points_at_the_same_place(tmp_path, task):
    csv = task.with_suffix(".csv")
    lines = csv.read_text().splitlines()
    a, b = lines[1].split(","), lines[2].split(",")
    b[1:4] = a[1:4]
    lines[2] = ",".join(b)
    csv.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("user file")
    r = run("build", str(task), "--out", str(out))
    assert r.returncode == 2 and "Q1 and Q2 are at the same place" in r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]  # nothing from the failed run


def test_missing_task_file(tmp_path):
    r = run("build", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "nope.toml" in r.stderr and "cannot read" in r.stderr


def test_new_writes_a_task_that_builds(tmp_path):
    r = run("new", "pointcloud", "--out", str(tmp_path / "t.toml"))
    assert r.returncode == 0
    text = (tmp_path / "t.toml").read_text()
    assert 'kind = "pointcloud"' in text and "sigma_ET_um" in text
    r = run("build", str(tmp_path / "t.toml"), "--out", str(tmp_path / "out"))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "my_pointcloud.xlsx").exists()
    r = run("new", "pointcloud", "--out", str(tmp_path / "t.toml"))
    assert r.returncode == 2 and "exists already" in r.stderr


def test_control_characters_and_huge_fields_are_named(tmp_path, task):
    set_field(task.with_suffix(".csv"), 2, 0, "Q\x072")
    r = run("build", str(task), "--out", str(tmp_path / "out"))
    assert r.returncode == 2 and "line 3, column 'id'" in r.stderr and "control character" in r.stderr
    set_field(task.with_suffix(".csv"), 2, 0, "x" * 200_000)
    r = run("build", str(task), "--out", str(tmp_path / "out"))
    assert r.returncode == 2 and "line 3" in r.stderr and "malformed CSV" in r.stderr


def test_recalc_refuses_a_workbook_with_an_entity_declaration(tmp_path, task):
    import zipfile

    assert run("build", str(task), "--out", str(tmp_path / "out")).returncode == 0
    good = zipfile.ZipFile(tmp_path / "out" / "t.xlsx")
    bad = tmp_path / "bad.xlsx"
    with zipfile.ZipFile(bad, "w") as z:
        for item in good.infolist():
            data = good.read(item.filename)
            if item.filename == "xl/workbook.xml":
                data = b'<!DOCTYPE x [<!ENTITY a "a"><!ENTITY b "&a;&a;&a;">]>' + data
            z.writestr(item, data)
    r = run("recalc", str(bad))
    assert r.returncode == 2 and "bad.xlsx" in r.stderr and "document type declaration" in r.stderr


def test_points_in_the_task_file_are_checked_like_a_csv(tmp_path, task):
    text = task.read_text().replace('file = "t.csv"', 'rows = [\n'
                                    '  {id = "A", x_mm = 0, y_mm = 0, z_mm = 0, nx = 1, ny = 0, nz = 0, probe = "P1"},\n'
                                    '  {id = "B", x_mm = "ten", y_mm = 0, z_mm = 0, nx = 1, ny = 0, nz = 0, probe = "P1"},\n]')
    task.write_text(text)
    r = run("build", str(task), "--out", str(tmp_path / "out"))
    assert r.returncode == 2 and "[points] rows #2 key 'x'" in r.stderr and "'ten' is not a number" in r.stderr
    task.write_text(text.replace('x_mm = "ten"', "x_mm = 10"))
    assert run("build", str(task), "--out", str(tmp_path / "out")).returncode == 0
