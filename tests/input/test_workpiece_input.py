"""The ``[workpiece]`` table (the factor W, docs/workpiece.md) as a user writes it: one clear message
naming the file, key and line and exit status 2 for what cannot be built (nothing written); warnings
for what builds but is probably a unit mix-up; ``enabled = false`` is the task without the table."""

from __future__ import annotations

import json
import sys

import pytest

from cmmwb.generator.cli import main

from tests.helpers import BAD_FILES

sys.path.insert(0, str(BAD_FILES))
from make_bad_files import POINTCLOUD_CSV, POINTCLOUD_TASK  # noqa: E402

PART = """
[workpiece]
material = "aluminium"
u_alpha_ppm_per_K = 1.0
T_degC = 23.5
u_T_K = 0.3
"""


def run(tmp_path, capsys, toml: str) -> tuple[int, str]:
    (tmp_path / "small.toml").write_text(toml)
    (tmp_path / "small.csv").write_text(POINTCLOUD_CSV)
    code = main(["build", str(tmp_path / "small.toml"), "--out", str(tmp_path / "out"), "--no-plots"])
    return code, capsys.readouterr().err.strip()


@pytest.mark.parametrize("change,where,says", [
    (('material = "aluminium"', 'material = "unobtainium"'), "[workpiece] material (line", "unknown material"),
    (('material = "aluminium"', ""), "[workpiece]", "alpha_ppm_per_K (1e-6/K) or material"),
    (("T_degC = 23.5", "T_degC = 23.5\nT_readings_degC = [23.4, 23.6]"), "[workpiece]", "not both"),
    (('material = "aluminium"', 'material = "aluminium"\nalpha_ppm_per_K = 22.0'), "[workpiece] material (line",
     "alpha_ppm_per_K or material (not both)"),
    (("T_degC = 23.5", 'T_degC = "warm"'), "[workpiece] T_degC (line", "must be a number"),
    (("u_T_K = 0.3", "u_T_K = -0.3"), "[workpiece] u_T_K (line", "must be >= 0"),
    (("T_degC = 23.5", "T_readings_degC = []"), "[workpiece] T_readings_degC", "one or more finite temperatures"),
    (("u_T_K = 0.3", "u_T_K = 0.3\ncorrected = false\nalpha_corr_ppm_per_K = 22"),
     "[workpiece] alpha_corr_ppm_per_K (line", "leave alpha_corr_ppm_per_K out"),
    (("u_T_K = 0.3", "u_T_K = 0.3\nenabled = 1"), "[workpiece] enabled (line", "true or false"),
    (("u_T_K = 0.3", "u_T_K = 0.3\nfixture_mm = [0, 0]"), "[workpiece] fixture_mm (line", "three numbers"),
    (("u_T_K = 0.3", "u_T_K = 0.3\ntemperature = 20"), "[workpiece] temperature (line", "unknown key"),
])
def test_a_bad_workpiece_names_the_key_and_writes_nothing(tmp_path, capsys, change, where, says):
    code, err = run(tmp_path, capsys, POINTCLOUD_TASK + PART.replace(*change))
    assert code == 2, err
    assert f"small.toml, {where}" in err and says in err, err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").glob("small.*"))


def test_a_temperature_in_kelvin_and_an_uncorrected_cmm_are_warned_about(tmp_path, capsys):
    code, err = run(tmp_path, capsys, POINTCLOUD_TASK + PART.replace("T_degC = 23.5", "T_degC = 296.65")
                    + "corrected = false\n")
    assert code == 0, err
    res = json.loads((tmp_path / "out" / "small.json").read_text())
    assert any("296.65 °C is outside 0-50 °C" in w and "[workpiece] T_degC" in w for w in res["warnings"])
    assert any("does not correct to 20 °C" in w and "in quadrature" in w for w in res["warnings"])


def test_W_off_is_one_key(tmp_path, capsys):
    """``enabled = false``: the numbers of the task without [workpiece], W = 0."""
    code, err = run(tmp_path, capsys, POINTCLOUD_TASK)
    assert code == 0, err
    plain = json.loads((tmp_path / "out" / "small.json").read_text())
    code, err = run(tmp_path / "off" if (tmp_path / "off").mkdir() is None else tmp_path, capsys,
                    POINTCLOUD_TASK + PART + "enabled = false\n")
    assert code == 0, err
    off = json.loads((tmp_path / "off" / "out" / "small.json").read_text())
    assert [d["components_um"] for d in off["distances"]] == [d["components_um"] for d in plain["distances"]]
    assert [d["u_um"] for d in off["distances"]] == [d["u_um"] for d in plain["distances"]]
    assert all(d["components_um"]["W"] == 0.0 for d in off["distances"])
