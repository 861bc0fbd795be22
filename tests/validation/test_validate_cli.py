"""`cmmwb simulate --validation` and `cmmwb validate` end to end: the simulated set's tasks give the
same U as the core, a right model holds, and bad input is one message naming the file and line,
exit status 2, nothing written."""

import json
import shutil

import pytest

from cmmwb.generator.cli import main
from cmmwb.xlfuncs import validation_sets as vsm
from cmmwb.xlfuncs.model import MPE1


@pytest.fixture(scope="module")
def valset(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("valset")
    assert main(["simulate", "--validation", "stepgauge,ring,sphere", "--seed", "5", "--runs", "1",
                 "--out", str(tmp / "set")]) == 0
    return tmp / "set"


def test_simulate_writes_the_tasks_the_results_and_the_truth(valset):
    names = {p.name for p in valset.iterdir()}
    assert {"validation_lengths.toml", "validation_lengths_points.csv", "validation_features.toml",
            "validation_features_points.csv", "results.csv", "truth.json"} <= names
    truth = json.loads((valset / "truth.json").read_text())
    assert truth["machine"]["sigma_R_um"] == MPE1.sigma_R_um and truth["planted"] == {}
    lines = [ln for ln in (valset / "results.csv").read_text().splitlines() if not ln.startswith("#")]
    assert lines[0].startswith("characteristic,workpiece,run,measured_mm,calibrated_mm,U_cal_um,k_cal,x1")
    assert len(lines) == 1 + 123 + 5


@pytest.fixture(scope="module")
def validated(valset, tmp_path_factory):
    out = tmp_path_factory.mktemp("val") / "out"
    code = main(["validate", str(valset / "results.csv"), "--task", str(valset / "validation_lengths.toml"),
                 "--task", str(valset / "validation_features.toml"), "--out", str(out)])
    assert code == 0
    return out, json.loads((out / "validation.json").read_text())


def test_the_tasks_give_the_cores_U(validated):
    """The U the task files give through their result records (pointcloud distances, the
    characteristic kind's diameters and distance) is the core's model_U of the same geometry:
    lengths to 1e-9; the fitted characteristics to 1e-7, the rounding floor of their central-
    difference sensitivities (eps x 800 mm / 1e-5 mm ~ 2e-8) under the points file's 1e-9 mm."""
    _, r = validated
    vs = vsm.build(("stepgauge", "ring", "sphere"), vsm.DEFAULT_PROBES)
    U = vsm.model_U(vs, MPE1)
    assert set(r["records"]) == set(U)
    for label, rec in r["records"].items():
        assert rec["U"] == pytest.approx(U[label], rel=1e-9 if "→" in label else 1e-7), label


def test_a_right_model_holds_and_says_why(validated):
    out, r = validated
    assert (out / "validation.xlsx").is_file()
    assert r["verdict"]["holds"] and r["verdict"]["verdict"] == "the model holds"
    assert r["verdict"]["rule"].startswith("ISO/TS 15530-4")
    assert len(r["rows"]) == 128 and r["locator"]["records"] == 123
    assert r["count"]["p_low_correlated"] is not None
    assert r["summary"].startswith("Verdict: the model holds")
    assert [w["E_n"] for w in r["worst"]] == sorted((row["E_n"] for row in r["rows"]), reverse=True)[:5]


def _bad(valset, tmp_path, capsys, edit, message):
    text = (valset / "results.csv").read_text().splitlines()
    head = next(i for i, ln in enumerate(text) if ln.startswith("characteristic"))
    text = edit(text, head)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(text) + "\n")
    out = tmp_path / "out"
    code = main(["validate", str(bad), "--task", str(valset / "validation_lengths.toml"),
                 "--task", str(valset / "validation_features.toml"), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "bad.csv" in err and message in err, err
    assert not out.exists()
    return err


def _set(text, head, row, column, value):
    cols = text[head].split(",")
    fields = text[head + row].split(",")
    fields[cols.index(column)] = value
    text[head + row] = ",".join(fields)
    return text


@pytest.mark.parametrize("column,value,message", [
    ("measured_mm", "twelve", "line {line}, column 'measured_mm': 'twelve' is not a number"),
    ("calibrated_mm", "nan", "line {line}, column 'calibrated_mm': 'nan' is not a finite number"),
    ("k_cal", "0", "line {line}, column 'k_cal': must be > 0"),
    ("U_cal_um", "-0.1", "line {line}, column 'U_cal_um': must be >= 0"),
    ("characteristic", "SGx.F1->SGq.F9", "line {line}, column 'characteristic': no result 'SGx.F1→SGq.F9'"),
    ("characteristic", "=1+1", "line {line}, column 'characteristic': no result '=1+1'"),
])
def test_a_bad_value_is_named_by_its_line_and_column(valset, tmp_path, capsys, column, value, message):
    line = 3 + 3      # two comment lines, the header, the third row
    _bad(valset, tmp_path, capsys, lambda t, h: _set(t, h, 3, column, value), message.format(line=line))


def test_two_certificates_for_one_characteristic_are_refused(valset, tmp_path, capsys):
    def edit(text, head):
        text = list(text)
        text.append(text[head + 1].replace(",1,", ",2,", 1))        # the same row, run 2
        return _set(text, head, len(text) - 1 - head, "U_cal_um", "0.9")
    _bad(valset, tmp_path, capsys, edit, "one certificate per characteristic")


def test_a_missing_column_is_named(valset, tmp_path, capsys):
    def edit(text, head):
        cols = text[head].split(",")
        k = cols.index("k_cal")
        return [",".join(f for j, f in enumerate(ln.split(",")) if j != k) if i >= head else ln
                for i, ln in enumerate(text)]
    _bad(valset, tmp_path, capsys, edit, "missing column 'k_cal'")


def test_a_failed_validation_leaves_the_folder_as_it_was(valset, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("kept")
    bad = tmp_path / "bad.csv"
    shutil.copy(valset / "results.csv", bad)
    bad.write_text(bad.read_text().replace(",1,", ",1,x", 1))
    code = main(["validate", str(bad), "--task", str(valset / "validation_lengths.toml"), "--out", str(out)])
    assert code == 2
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt"]


def test_a_planted_squareness_fails_the_validation_and_is_named(tmp_path, capsys):
    """`cmmwb simulate --validation ballplate --effect squareness_xy=20` then `cmmwb validate`: the
    command succeeds (exit 0), its verdict is "does not hold", the cause the locator's named
    effect with its estimate, the next step to compensate or calibrate it."""
    assert main(["simulate", "--validation", "ballplate", "--effect", "squareness_xy=20", "--seed", "4",
                 "--out", str(tmp_path / "set")]) == 0
    capsys.readouterr()
    assert main(["validate", str(tmp_path / "set" / "results.csv"), "--task",
                 str(tmp_path / "set" / "validation_lengths.toml"), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    r = json.loads((tmp_path / "out" / "validation.json").read_text())
    v = r["verdict"]
    assert not v["holds"] and v["causes"][0]["name"] == "squareness_xy"
    assert abs(v["causes"][0]["estimate"] - 20.0) < 3 * v["causes"][0]["u"]
    assert "Cause: the locator names squareness_xy" in out and "Next step:" in out
