"""The loop a lab runs (docs/validate.md section 6, generator/validation/loop.py, `cmmwb demo`):
a machine worse than its type-B model (MPE1 with sigma_R 0.35 um, sigma_ET 0.5 um) -> validation
of the starting model on held-back workpieces fails, naming the cause (U too small, evenly) ->
calibrate on the verification recordings (ISO 10360-2 with three styli, a ball plate) -> the
fitted task -> the same validation holds."""

import pytest

from cmmwb.generator.validation.loop import TRUTH, run_loop


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    return run_loop(tmp_path_factory.mktemp("loop"), workbook=False)


def test_the_starting_model_does_not_hold_and_the_cause_is_its_U(loop):
    v = loop["before"]["verdict"]
    assert not v["holds"]
    assert v["causes"][0]["kind"] == "noise" and v["causes"][0]["scale"] > 1.3
    assert "cmmwb calibrate" in v["next_step"]


def test_calibrate_finds_the_machines_own_repeatability_and_translation_errors(loop):
    est = {h["name"]: h for h in loop["calibration"]["hyper_parameters"]}
    for name in ("sigma_R_um", "sigma_ET_um"):
        h = est[name]
        assert h["status"] == "estimated" and abs(h["estimate"] - getattr(TRUTH, name)) < 3 * h["u"], h


def test_the_fitted_model_holds_on_the_same_workpieces(loop):
    after = loop["after"]
    assert after["verdict"]["holds"]
    assert after["count"]["share"] > loop["before"]["count"]["share"]
    assert {t["file"] for t in after["tasks"]} == {"fitted.toml", "fitted_features.toml"}
