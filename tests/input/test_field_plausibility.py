"""Field finish (issue 25), plausibility: values far outside what coordinate measuring machines
have (a µm/mm mix-up such as sigma_R_um = 200, a length scale in m) build as given but are warned
about on stderr and in the JSON ``warnings``; so is a probe without offset_mm.  The ranges are one
table (xlfuncs.limits.PLAUSIBLE), documented in docs/input_limits.md."""

from __future__ import annotations

import json
import re
import sys

import pytest

from cmmwb.generator.cli import main
from cmmwb.xlfuncs.limits import PLAUSIBLE, plausibility_problem

from tests.helpers import BAD_FILES, ROOT

sys.path.insert(0, str(BAD_FILES))
from make_bad_files import POINTCLOUD_CSV, POINTCLOUD_TASK  # noqa: E402


def build(tmp_path, capsys, toml: str) -> tuple[dict, list[str]]:
    (tmp_path / "small.toml").write_text(toml)
    (tmp_path / "small.csv").write_text(POINTCLOUD_CSV)
    code = main(["build", str(tmp_path / "small.toml"), "--out", str(tmp_path / "out"), "--no-plots"])
    err = capsys.readouterr().err.strip()
    assert code == 0, err
    return json.loads((tmp_path / "out" / "small.json").read_text()), err.splitlines() if err else []


def test_the_paper_values_give_no_warning(tmp_path, capsys):
    res, err = build(tmp_path, capsys, POINTCLOUD_TASK)
    assert res["warnings"] == [] and err == []


def test_sigma_R_200_um_builds_with_its_numbers_and_a_warning_naming_the_key(tmp_path, capsys):
    """200 µm of repeatability is a µm/mm mix-up: built as given (u grows as it must), warned."""
    res, err = build(tmp_path, capsys, POINTCLOUD_TASK.replace("sigma_R_um = 0.2", "sigma_R_um = 200"))
    assert len(res["warnings"]) == 1
    w = res["warnings"][0]
    assert w.startswith(f"{tmp_path / 'small.toml'}, [parameters] sigma_R_um: sigma_R_um = 200 µm is larger than")
    assert "(0.001 to 50 µm); built as given" in w and "1000 times too large" in w
    assert err == [f"cmmwb: warning: {w}"]
    # u_R of a distance between two points is sqrt(2) sigma_R (Forbes 2025 eq. (14)): still computed
    d = res["distances"][0]
    assert d["components_um"]["R"] == pytest.approx(200 * 2 ** 0.5, rel=1e-12)


@pytest.mark.parametrize("old,new,key,side", [
    ("lambda_ET_mm = 150", "lambda_ET_mm = 0.15", "lambda_ET_mm", "smaller"),     # metres for mm
    ("lambda_ET_mm = 150", "lambda_ET_mm = 150000000", "lambda_ET_mm", "larger"),  # µm for mm (and > 100 m)
    ("sigma_S_ppm = 0.7", "sigma_S_ppm = 700", "sigma_S_ppm", "larger"),          # µm/mm for ppm
    ("sigma_ET_um = 0.3", "sigma_ET_um = 0.0003", "sigma_ET_um", "smaller"),       # mm for µm
])
def test_values_orders_of_magnitude_off_are_warned_about(tmp_path, capsys, old, new, key, side):
    res, err = build(tmp_path, capsys, POINTCLOUD_TASK.replace(old, new))
    assert [w for w in res["warnings"] if f"[parameters] {key}: {key} = " in w and f"is {side} than" in w], res
    assert len(err) == len(res["warnings"])


def test_a_probe_without_offset_is_warned_about(tmp_path, capsys):
    toml = POINTCLOUD_TASK.replace('id = "P2"\noffset_mm = [30.0, 0.0, -20.0]\n', 'id = "P2"\n')
    res, err = build(tmp_path, capsys, toml)
    assert res["warnings"] == [f"{tmp_path / 'small.toml'}, [[probes]] #2 (probe P2): probe P2 has no offset_mm: "
                               "taken as [0, 0, 0] mm, the stylus tip at the ram's reference point: the rotation "
                               "errors (ER, Forbes 2025 eq. (25)) act through the offset and then contribute "
                               "nothing; give the probe's offset_mm"]
    assert err == [f"cmmwb: warning: {res['warnings'][0]}"]


def test_a_task_without_probes_but_with_rotation_errors_is_warned_about(tmp_path, capsys):
    toml = POINTCLOUD_TASK.replace("sigma_ET_um = 0.3", "sigma_ET_um = 0.3\nsigma_ER_urad = 4\nlambda_ER_mm = 400")
    toml = toml[:toml.index("[[probes]]")] + toml[toml.index("[points]"):]
    csv = POINTCLOUD_CSV.replace(",P2\n", ",P1\n")
    (tmp_path / "small.toml").write_text(toml)
    (tmp_path / "small.csv").write_text(csv.replace(",probe\n", "\n", 1).replace(",P1\n", "\n"))
    assert main(["build", str(tmp_path / "small.toml"), "--out", str(tmp_path / "out"), "--no-plots"]) == 0, \
        capsys.readouterr().err
    res = json.loads((tmp_path / "out" / "small.json").read_text())
    assert len(res["warnings"]) == 1 and "[[probes]]: no [[probes]]: one probe P1 with offset [0, 0, 0] mm" \
        in res["warnings"][0]


def test_a_probe_offset_of_metres_is_warned_about(tmp_path, capsys):
    res, _ = build(tmp_path, capsys, POINTCLOUD_TASK.replace("offset_mm = [30.0, 0.0, -20.0]",
                                                             "offset_mm = [3000.0, 0.0, -20.0]"))
    assert len(res["warnings"]) == 1 and "(probe P2) offset_mm: offset_mm [3000.0, 0.0, -20.0] is 3000.07 mm" \
        in res["warnings"][0]


def test_zero_switches_a_factor_off_and_is_never_warned_about():
    assert all(plausibility_problem(k, 0.0) is None for k in PLAUSIBLE)
    assert plausibility_problem("sigma_R_um", 0.2) is None
    assert plausibility_problem("not_a_key", 1e30) is None


def test_diagnose_warns_about_an_implausible_task_in_its_json(tmp_path, capsys):
    (tmp_path / "t.toml").write_text(POINTCLOUD_TASK.replace("sigma_R_um = 0.2", "sigma_R_um = 200"))
    assert main(["simulate", "--layout", "iso10360", "--sigma-um", "0.3", "--out", str(tmp_path / "rec.csv")]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(tmp_path / "rec.csv"), "--task", str(tmp_path / "t.toml"), "--out",
                 str(tmp_path / "d"), "--no-plots", "--no-workbook"]) == 0
    err = capsys.readouterr().err
    d = json.loads((tmp_path / "d" / "diagnosis.json").read_text())
    assert len(d["warnings"]) == 1 and "sigma_R_um = 200 µm is larger than" in d["warnings"][0]
    assert f"cmmwb: warning: {d['warnings'][0]}" in err


def test_the_ranges_are_documented_in_input_limits():
    """docs/input_limits.md shows every row of PLAUSIBLE with its numbers."""
    doc = (ROOT / "docs" / "input_limits.md").read_text()
    for key, (lo, hi, unit) in PLAUSIBLE.items():
        row = re.search(rf"^\| `{re.escape(key)}` \| ([^|]+) \| ([^|]+) \| ([^|]+) \|", doc, re.MULTILINE)
        assert row, key
        assert float(row.group(1).strip()) == lo and float(row.group(2).strip()) == hi, (key, row.group(0))
        assert row.group(3).strip() == unit, (key, row.group(0))
