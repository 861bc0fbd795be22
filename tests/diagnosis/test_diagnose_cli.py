"""`cmmwb simulate` and `cmmwb diagnose` end to end, and the demonstration of `cmmwb demo`."""

import json

import pytest

from cmmwb.generator.diagnosis.run import demo
from cmmwb.xlfuncs.model import MPE1

from tests.helpers import run_cmmwb as run
from tests.helpers.tasks import machine_task_toml

TASK = machine_task_toml(MPE1, [("P1", (0.0, 0.0, -50.0))])


def test_simulate_then_diagnose_finds_the_planted_warm_records_effect(tmp_path):
    """Thermal expansion planted in an ISO 10360-2 test whose last round is warm (23-24 °C)."""
    (tmp_path / "task.toml").write_text(TASK)
    p = run("simulate", "--layout", "iso10360", "--task", "task.toml", "--effect", "thermal_expansion=6",
            "--temperature-C", "20,24", "--seed", "4", "--out", "rec.csv", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "105 length records" in p.stdout
    text = (tmp_path / "rec.csv").read_text()
    assert text.startswith("# cmmwb") and "temperature_C" in text.splitlines()[3]
    p = run("diagnose", "rec.csv", "--task", "task.toml", "--out", "out", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    j = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert j["mismatch"] and j["effects"][0]["name"] == "thermal_expansion"
    assert abs(j["effects"][0]["estimate"] - 6.0) <= 3 * j["effects"][0]["u"]
    assert p.stdout.startswith("the records disagree with the simulation")
    names = {f.name for f in (tmp_path / "out").iterdir()}
    assert {"diagnosis.json", "diagnosis.xlsx", "residuals_before_after.png", "residuals_by_quantity.png",
            "effect_thermal_expansion.png"} <= names
    assert not [n for n in names if n.startswith(".") and n != ".cmmwb-manifest.json"]   # no staging left


def test_sigma_shorthand_and_point_records(tmp_path):
    p = run("simulate", "--layout", "ballplate", "--sigma-um", "0.2", "--effect", "offset_drift=2,0,0",
            "--hours", "3", "--seed", "2", "--out", "plate.csv", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    p = run("diagnose", "plate.csv", "--sigma-um", "0.2", "--out", "out", "--no-plots", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    j = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert j["kind"] == "point" and j["effects"][0]["name"] == "offset_drift"
    vx = j["effects"][0]["estimate"][0]
    assert abs(vx - 2.0) <= 3 * j["effects"][0]["u"][0]


@pytest.mark.parametrize("effect,words", [
    ("bogus=1", ["unknown effect 'bogus'"]),
    ("scale=abc", ["'abc' is not a number"]),
    ("probe_qualification=1,2,3", ["PROBE:dx,dy,dz"]),
    ("offset_drift=1,2", ["offset_drift", "point-record effect"]),
])
def test_simulate_rejects_bad_effects(tmp_path, effect, words):
    p = run("simulate", "--layout", "iso10360", "--effect", effect, "--out", "rec.csv", cwd=tmp_path)
    if effect.startswith("offset_drift"):
        p = run("simulate", "--layout", "iso10360", "--effect", "offset_drift=1,2,0", "--out", "rec.csv",
                cwd=tmp_path)
    assert p.returncode == 2
    for w in words:
        assert w in p.stderr
    assert not (tmp_path / "rec.csv").exists()


def test_demo_finds_the_concealed_effect_and_reports_the_aliased_one(tmp_path, capsys):
    files = demo(tmp_path / "diagnose")
    out = capsys.readouterr().out
    concealed = json.loads((tmp_path / "diagnose" / "concealed" / "diagnosis.json").read_text())
    assert [e["name"] for e in concealed["effects"]] == ["squareness_xy"]
    assert "squareness error between x and y" in out and "diagonal lengths" in out
    aliased = json.loads((tmp_path / "diagnose" / "aliased" / "diagnosis.json").read_text())
    item = next(x for x in aliased["not_identifiable"] if x["name"] == "EBX")
    assert item["aliased_with"] == "scale_x" and "second probe offset" in item["reason"]
    assert all(f.exists() for f in files)
    # the demo's files rerun with the command line give the same answer
    case = tmp_path / "diagnose" / "concealed"
    p = run("diagnose", "recordings.csv", "--task", "task.toml", "--out", "again", "--no-plots", cwd=case)
    assert p.returncode == 0, p.stderr
    again = json.loads((case / "again" / "diagnosis.json").read_text())
    assert again["effects"][0]["estimate"] == pytest.approx(concealed["effects"][0]["estimate"], rel=1e-9)


def test_diagnose_refuses_an_alpha_name_above_alpha(tmp_path):
    assert run("simulate", "--layout", "iso10360", "--out", "rec.csv", cwd=tmp_path).returncode == 0
    p = run("diagnose", "rec.csv", "--sigma-um", "0.3", "--alpha-name", "0.05", "--out", "diag", cwd=tmp_path)
    assert p.returncode == 2 and "--alpha-name" in p.stderr and "0.05" in p.stderr
    assert not (tmp_path / "diag").exists()
