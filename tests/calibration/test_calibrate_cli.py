"""`cmmwb calibrate` end to end: a ball plate with two probes, and bad input (exit 2, one message
naming the file and where, nothing written)."""

import json

from cmmwb.xlfuncs.model import MPE1

from tests.helpers import run_cmmwb
from tests.helpers.tasks import machine_task_toml

TASK = machine_task_toml(MPE1, [("P1", (0.0, 20.0, -30.0)), ("P2", (0.0, -20.0, -30.0))])


def run(*args, cwd):
    return run_cmmwb(*args, cwd=cwd, env={"OPENBLAS_NUM_THREADS": "1"})


def test_a_ball_plate_with_two_probes_gives_estimates_and_says_what_it_cannot(tmp_path):
    (tmp_path / "task.toml").write_text(TASK)
    p = run("simulate", "--layout", "ballplate", "--task", "task.toml", "--seed", "3", "--out", "plate.csv",
            cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    p = run("calibrate", "plate.csv", "--task", "task.toml", "--mpe", "1.5,333", "--no-workbook", "--out", "cal",
            cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "Estimated: sigma_R_um" in p.stdout and "Not identifiable" in p.stdout
    result = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    status = {h["name"]: h for h in result["hyper_parameters"]}
    assert status["sigma_R_um"]["status"] == "estimated" and status["sigma_R_um"]["u"] > 0
    # a ball plate has no normals: the probing factor is not identifiable, and the advice says what would
    assert status["sigma_P0_um"]["status"] == "not identifiable" and status["sigma_P0_um"]["advice"]
    assert result["mpe_check"]["fitted"]["C_max"] > 0
    assert (tmp_path / "cal" / "fitted.toml").is_file()


def test_text_in_a_number_cell_names_file_and_line_and_writes_nothing(tmp_path):
    (tmp_path / "task.toml").write_text(TASK)
    p = run("simulate", "--layout", "ballplate", "--task", "task.toml", "--out", "plate.csv", cwd=tmp_path)
    lines = (tmp_path / "plate.csv").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line and not line.startswith("#") and not line.startswith("id"))
    cells = lines[k].split(",")
    cells[1] = "abc"
    lines[k] = ",".join(cells)
    (tmp_path / "plate.csv").write_text("\n".join(lines) + "\n")
    p = run("calibrate", "plate.csv", "--task", "task.toml", "--out", "cal", cwd=tmp_path)
    assert p.returncode == 2
    assert "plate.csv" in p.stderr and f"line {k + 1}" in p.stderr
    assert not (tmp_path / "cal").exists() or not any((tmp_path / "cal").iterdir())


def test_an_unknown_effect_and_a_bad_mpe_are_refused(tmp_path):
    (tmp_path / "task.toml").write_text(TASK)
    run("simulate", "--layout", "ballplate", "--task", "task.toml", "--out", "plate.csv", cwd=tmp_path)
    p = run("calibrate", "plate.csv", "--task", "task.toml", "--effects", "warp_drive", "--out", "cal", cwd=tmp_path)
    assert p.returncode == 2 and "unknown effect 'warp_drive'" in p.stderr
    p = run("calibrate", "plate.csv", "--task", "task.toml", "--mpe", "1.5,abc", "--out", "cal", cwd=tmp_path)
    assert p.returncode == 2 and "--mpe" in p.stderr
