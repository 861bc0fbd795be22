"""The loop closed (docs/calibrate.md): a planted scale error -> the locator names it -> its
compensation is written into the fitted task -> u(d) and chi-square both improve, and the
recomputed workbooks (the calibration's and the pointcloud workbook rebuilt from the fitted task)
agree with their JSON in four engines (the core, `formulas`, LibreOffice, Gnumeric)."""

import pytest

from cmmwb.generator.calibration.run import run_calibrate
from cmmwb.generator.cli import build_task
from cmmwb.generator.diagnosis.run import load_model
from cmmwb.generator.workbook.recalc import results_rows
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.recordings import write_recordings
from cmmwb.xlfuncs.model import MPE1

from tests.helpers import ENGINES, close, recalc
from tests.helpers.tasks import parameters_toml

TASK = """[task]
kind = "pointcloud"
name = "machine"
notes = []

[mpe]
A_um = 1.5
B_mm = 333
K = 2
L_max_mm = 1000

""" + parameters_toml(MPE1) + """
[[probes]]
id = "P1"
offset_mm = [0.0, 0.0, -50.0]

[points]
file = "pts.csv"
"""
PLANTED_SCALE = 8.0     # µm/m, about 11 sigma_S of the task


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("loop")
    (tmp / "task.toml").write_text(TASK)
    (tmp / "pts.csv").write_text("id,x,y,z,nx,ny,nz,probe\nA,100,100,100,-1,0,0,P1\nB,600,100,100,1,0,0,P1\n"
                                   "C,600,500,100,0,1,0,P1\nD,100,500,400,0,0,1,P1\n")
    model, label = load_model(str(tmp / "task.toml"), None)
    probes = model.probes
    iso = sm.simulate(sm.layout("iso10360", probes), model.params, {"scale": PLANTED_SCALE}, seed=4)
    step = sm.simulate(sm.layout("stepgauge", probes), model.params, {}, seed=5)
    write_recordings(iso, tmp / "iso.csv")
    write_recordings(step, tmp / "step.csv")
    from cmmwb.generator.calibration.run import parse_mpe
    from cmmwb.generator.taskfile import read_toml

    mpe = parse_mpe(None, read_toml(tmp / "task.toml"), probes)
    result, files = run_calibrate([tmp / "iso.csv", tmp / "step.csv"], model, tmp / "cal",
                                  task_path=tmp / "task.toml", task_label=label, mpe=mpe)
    return tmp, result, files


def test_the_locator_names_the_planted_scale_error(loop):
    _, result, _ = loop
    (eff,) = result["effects"]
    assert eff["name"] == "scale" and eff["file"] == "iso"
    assert abs(eff["estimate"][0] - PLANTED_SCALE) < 3 * eff["u"][0]


def test_the_compensation_is_written_into_the_fitted_task(loop):
    tmp, result, files = loop
    import tomllib

    fitted = tomllib.loads((tmp / "cal" / "fitted.toml").read_text())
    (change,) = result["changes"]
    assert change["parameter"] == "sigma_S_ppm" and result["feedback"] == "compensate"
    # the scale factor keeps only the correction's u
    assert close(fitted["parameters"]["sigma_S_ppm"], result["effects"][0]["u"][0])
    assert fitted["parameters"]["sigma_S_ppm"] < 0.7
    assert (tmp / "cal" / "compensated_iso.csv").is_file()
    assert any("cmmwb calibrate" in n for n in fitted["task"]["notes"])


def test_chi2_and_u_of_d_improve(loop):
    _, result, _ = loop
    c = result["chi2"]
    assert c["after"] < c["before"]
    # the task does not explain the records (the planted scale), the fitted compensated one does
    assert abs(c["after"] / c["dof_after"] - 1) < abs(c["before"] / c["dof_before"] - 1)
    ud = result["u_d"]
    for d, b, a, unc in zip(ud["d_mm"], ud["before_um"], ud["after_um"], ud["uncompensated_um"]):
        if d >= 300.0:          # where the scale dominates u(d)
            assert a < b, (d, a, b)
        if d > 0:               # against carrying the error uncompensated as a factor
            assert a < unc, (d, a, unc)


@pytest.mark.parametrize("engine", ENGINES)
def test_the_calibration_workbook_agrees_with_its_json(loop, engine):
    tmp, result, _ = loop
    rows = {r["quantity"]: r for r in results_rows(recalc(tmp / "cal" / "calibration.xlsx", engine))}
    m = result["mpe_check"]["fitted"]
    for key, value in (("C_max", m["C_max"]), ("d_at_max_mm", m["d_at_max_mm"]), ("margin", m["margin"]),
                       ("u_after_at_L_max_um", result["u_d"]["after_um"][-1])):
        assert close(rows[key]["value"], value), (engine, key, rows[key]["value"], value)
    for h in result["hyper_parameters"]:
        if h["status"] == "estimated":
            assert close(rows[h["name"]]["value"], h["estimate"])


@pytest.mark.parametrize("engine", ENGINES)
def test_the_rebuilt_pointcloud_workbook_agrees_in_every_engine(loop, tmp_path, engine):
    tmp, result, _ = loop
    results, _ = build_task(tmp / "cal" / "fitted.toml", tmp_path, plots=False)
    rows = results_rows(recalc(tmp_path / "machine.xlsx", engine))
    assert len(rows) == len(results["distances"]) > 0
    for row, d in zip(rows, results["distances"]):
        for key in ("d_mm", "u_um", "U_um"):
            assert close(row[key], d[key]), (engine, d["from"], d["to"], key)
    # the rebuilt workbook computes with the fitted task's parameters
    fitted = pc.Parameters(**result["fitted_parameters"])
    cloud_task = build_task(tmp / "task.toml", tmp_path / "task", plots=False)[0]
    for before, after in zip(cloud_task["distances"], results["distances"]):
        assert after["components_um"]["S"] < before["components_um"]["S"]   # sigma_S: the correction's u
    assert fitted.sigma_S_ppm < 0.7
