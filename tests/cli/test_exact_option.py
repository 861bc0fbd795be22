"""Exact computation on demand (issue 13): the task key ``[feature] va_method`` and the flags
``cmmwb build --exact`` / ``cmmwb diagnose --exact`` switch off the approximations that large
inputs otherwise get (low-rank GP factors of V_A; the structured record covariance), and the
approximate results carry their error estimate.  The size thresholds are lowered here so that
small inputs take the large-input code paths."""

import json

import pytest

from cmmwb.generator.cli import build_task, main
from cmmwb.generator.feature import job as feature_job
from cmmwb.xlfuncs.locator import model as locator_model
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.recordings import write_recordings

from tests.helpers.clouds import MPE1, PAIR
from tests.helpers.tasks import write_bore_task


@pytest.fixture
def large(monkeypatch):
    """120 points count as 'large': blocked V_A above 50, low-rank GP factors above 100."""
    monkeypatch.setattr(feature_job, "DENSE_MAX_POINTS", 50)
    monkeypatch.setattr(feature_job, "LOWRANK_MIN_POINTS", 100)
    monkeypatch.delenv(feature_job.VA_METHOD_ENV, raising=False)


def with_va_method(task, value: str):
    text = task.read_text()
    task.write_text(text.replace('type = "cylinder"\n', f'type = "cylinder"\nva_method = "{value}"\n', 1))
    return task


def test_auto_uses_the_low_rank_factor_and_reports_its_error_bound(tmp_path, large):
    res, _ = build_task(write_bore_task(tmp_path), tmp_path / "out", plots=False)
    a = res["feature"]["approximation"]
    assert a["method"] == "nystrom-pivoted-cholesky"
    assert set(a["relative_error_bound"]) == {"ET", "ER", "P"}
    assert 0 < max(a["relative_error_bound"].values()) <= 1e-6


def test_the_task_key_va_method_exact_gives_exact_numbers(tmp_path, large):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    low, _ = build_task(write_bore_task(tmp_path / "a"), tmp_path / "a" / "out", plots=False)
    ex, _ = build_task(with_va_method(write_bore_task(tmp_path / "b"), "exact"), tmp_path / "b" / "out",
                       plots=False)
    assert "approximation" not in ex["feature"]
    bound = max(low["feature"]["approximation"]["relative_error_bound"].values())
    for n, u in ex["feature"]["u"].items():
        assert abs(low["feature"]["u"][n] - u) <= max(bound, 1e-12) * u, n


def test_the_task_key_wins_over_the_environment(tmp_path, large, monkeypatch):
    monkeypatch.setenv(feature_job.VA_METHOD_ENV, "lowrank")
    ex, _ = build_task(with_va_method(write_bore_task(tmp_path), "exact"), tmp_path / "out", plots=False)
    assert "approximation" not in ex["feature"]


def test_the_task_key_lowrank_applies_below_the_size_threshold(tmp_path, monkeypatch):
    monkeypatch.setattr(feature_job, "DENSE_MAX_POINTS", 50)
    monkeypatch.delenv(feature_job.VA_METHOD_ENV, raising=False)
    res, _ = build_task(with_va_method(write_bore_task(tmp_path), "lowrank"), tmp_path / "out", plots=False)
    assert "approximation" in res["feature"]


def test_a_bad_va_method_names_the_key_and_exits_2(tmp_path, capsys):
    task = with_va_method(write_bore_task(tmp_path), "fast")
    assert main(["build", str(task), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "[feature] va_method" in err and "'fast'" in err and "exact" in err
    assert not (tmp_path / "out").exists()


def test_build_exact_overrides_the_task(tmp_path, large, capsys):
    task = with_va_method(write_bore_task(tmp_path), "lowrank")
    assert main(["build", str(task), "--out", str(tmp_path / "out"), "--no-plots", "--exact"]) == 0
    res = json.loads((tmp_path / "out" / "bore120.json").read_text())
    assert "approximation" not in res["feature"]


@pytest.fixture
def point_records(tmp_path, monkeypatch):
    """300 point records (900 observations) counted as large: the structured path above 600."""
    monkeypatch.setattr(locator_model, "STRUCTURED_MIN_OBS", 600)
    rec = sm.simulate(sm.scan(PAIR, points=300), MPE1, {"scale": 30.0, "probe_radius": 8.0}, seed=3)
    path = tmp_path / "scan.csv"
    write_recordings(rec, path)
    task = tmp_path / "machine.toml"
    from cmmwb.generator.diagnosis.run import task_toml

    task.write_text(task_toml(MPE1, PAIR, "machine", "MPE1 with two probes"))
    return path, task


def diagnose_json(tmp_path, point_records, *flags) -> dict:
    rec, task = point_records
    out = tmp_path / ("exact" if flags else "default")
    assert main(["diagnose", str(rec), "--task", str(task), "--out", str(out), "--no-plots",
                 "--no-workbook", *flags]) == 0
    return json.loads((out / "diagnosis.json").read_text())


def test_diagnose_reports_the_structured_error_bound_and_exact_drops_it(tmp_path, point_records):
    approx = diagnose_json(tmp_path, point_records)
    exact = diagnose_json(tmp_path, point_records, "--exact")
    a = approx["approximation"]
    assert 0 < a["chi2_relative_error_bound"] <= 1e-8 and a["covariance_error_bound_um2"] > 0
    assert "approximation" not in exact
    assert approx["chi2_before"] == pytest.approx(exact["chi2_before"], rel=1e-8)


def test_the_dense_memory_estimate_covers_the_measured_peaks():
    """The guard in front of the dense path (also `diagnose --exact`) does not underestimate
    the peaks measured by bench/bench_million.py equal: 2,777 MB at 2,000 point records and
    15,319 MB at 5,000 (ru_maxrss, interpreter included)."""
    from cmmwb.xlfuncs.memory import diagnose_bytes

    assert diagnose_bytes("point", 2_000) >= 2_777 * 2**20
    assert diagnose_bytes("point", 5_000) >= 15_319 * 2**20
    assert diagnose_bytes("point", 5_000) <= 1.3 * 15_319 * 2**20     # and is no wild overestimate
