"""`cmmwb calibrate` and `cmmwb diagnose` with the artefact's temperature (the factor W,
docs/workpiece.md): a steel step gauge recorded at 18-25 °C whose expansion coefficient is 1.5e-6/K
off the one the CMM corrects with.  The records' temperature_C enter W; the spread u(alpha), u(T) is
not identifiable from one artefact (one draw each), and says why; the locator's thermal_expansion
finding is fed back into W (compensate: the artefact's alpha; factor: u(alpha) grows)."""

import json
import tomllib

import pytest

from cmmwb.xlfuncs.model import MPE1

from tests.helpers import run_cmmwb
from tests.helpers.tasks import machine_task_toml

STEEL = "\n[workpiece]\nmaterial = \"steel\"\nu_alpha_ppm_per_K = 1.0\nT_degC = 20.0\nu_T_K = 0.1\n"
TASK = machine_task_toml(MPE1, [("P1", (0.0, 0.0, -20.0))]) + STEEL


def run(*args, cwd):
    return run_cmmwb(*args, cwd=cwd, env={"OPENBLAS_NUM_THREADS": "1"})


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("W")
    (folder / "task.toml").write_text(TASK)
    p = run("simulate", "--layout", "stepgauge", "--task", "task.toml", "--temperature-C", "18,25",
            "--effect", "thermal_expansion=1.5", "--out", "sg.csv", cwd=folder)
    assert p.returncode == 0, p.stderr
    return folder


@pytest.mark.parametrize("feedback", ["compensate", "factor"])
def test_the_artefacts_alpha_is_found_and_fed_back_into_W(recorded, feedback):
    p = run("calibrate", "sg.csv", "--task", "task.toml", "--feedback", feedback, "--no-workbook", "--out",
            f"cal_{feedback}", cwd=recorded)
    assert p.returncode == 0, p.stderr
    r = json.loads((recorded / f"cal_{feedback}" / "calibration.json").read_text())
    h = {x["name"]: x for x in r["hyper_parameters"]}
    for name in ("u_alpha_ppm_per_K", "u_T_K"):
        assert h[name]["status"] == "not identifiable", h[name]
        assert "one draw" in h[name]["reason"] and h[name]["advice"], h[name]
    (effect,) = [e for e in r["effects"] if e["name"] == "thermal_expansion"]
    b, u = effect["estimate"][0], effect["u"][0]
    assert abs(b - 1.5) < 3 * u and u < 0.5                           # the planted 1.5e-6/K
    (change,) = r["changes"]
    assert change["parameter"] == "u_alpha_ppm_per_K" and change["effects"] == ["thermal_expansion"]
    fitted = tomllib.loads((recorded / f"cal_{feedback}" / "fitted.toml").read_text())
    wp = fitted["workpiece"]
    if feedback == "compensate":
        # the CMM now corrects with the artefact's own alpha; what is left is the correction's u
        assert wp["alpha_ppm_per_K"] == pytest.approx(11.5 + b, rel=1e-12)
        assert wp["alpha_corr_ppm_per_K"] == wp["alpha_ppm_per_K"]
        assert wp["u_alpha_ppm_per_K"] == pytest.approx(u, rel=1e-12)
    else:
        # carried as an influence: u^2(alpha) + b^2 + u(b)^2, alpha as it was
        assert "alpha_ppm_per_K" not in wp and wp["material"] == "steel"
        assert wp["u_alpha_ppm_per_K"] == pytest.approx((1.0 + b * b + u * u) ** 0.5, rel=1e-12)
    assert "u_alpha_ppm_per_K" not in fitted["parameters"]


def test_records_at_one_temperature_say_the_expansion_is_a_scale_error(tmp_path):
    (tmp_path / "task.toml").write_text(TASK.replace("T_degC = 20.0", "T_degC = 23.0"))
    p = run("simulate", "--layout", "stepgauge", "--task", "task.toml", "--temperature-C", "23",
            "--out", "sg.csv", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    p = run("calibrate", "sg.csv", "--task", "task.toml", "--effects", "none", "--no-workbook", "--out", "cal",
            cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    h = {x["name"]: x for x in json.loads((tmp_path / "cal" / "calibration.json").read_text())["hyper_parameters"]}
    assert h["u_alpha_ppm_per_K"]["status"] == "not identifiable"
    assert "one temperature" in h["u_alpha_ppm_per_K"]["reason"]


def test_diagnose_takes_the_records_temperatures_into_W(recorded):
    """The artefact's u(alpha) = 1e-6/K over records 2 to 5 K from 20 °C is part of the records'
    covariance: the same records are less surprising (smaller chi-square) than against the machine
    alone, and the planted 1.5e-6/K is still named."""
    (recorded / "machine.toml").write_text(TASK.replace(STEEL, ""))
    got = {}
    for task in ("task.toml", "machine.toml"):
        p = run("diagnose", "sg.csv", "--task", task, "--no-workbook", "--out", f"diag_{task[:-5]}", cwd=recorded)
        assert p.returncode == 0, p.stderr
        got[task] = json.loads((recorded / f"diag_{task[:-5]}" / "diagnosis.json").read_text())
    assert got["task.toml"]["chi2_before"] < 0.9 * got["machine.toml"]["chi2_before"]
    assert "thermal_expansion" in [e["name"] for e in got["machine.toml"]["effects"]]
