"""The ``discrepancy`` candidate (docs/recordings.md section 7): a smooth field over the ram
position, tried last, only when the named effects leave the mismatch unexplained."""

import dataclasses

import numpy as np

from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import simulate as sm

from tests.helpers.clouds import MPE1, ONE
from tests.helpers.locator import iso, u_effect


def bumped(seed: int, height_um: float = 6.0, width_mm: float = 150.0):
    """ISO 10360 lengths with a localized bump of the x error (a Gaussian in ram x), a cause no
    named candidate matches; the measured length sees n_x (delta(end 2) - delta(end 1)).  The
    lengths carry no normals (as many exports give them): with normals, the reversal candidate
    (section 7) takes the part of the bump that the lengths probed from both sides share."""
    L, model = iso()
    rec = sm.simulate(L, MPE1, {}, seed=seed)
    P = L.probes[0].offset_mm if hasattr(L.probes[0], "offset_mm") else (0.0, 0.0, 0.0)
    U1, U2 = rec.X1_mm - np.asarray(P), rec.X2_mm - np.asarray(P)
    x0 = float(np.quantile(np.r_[U1[:, 0], U2[:, 0]], 0.8))   # off the centre the lengths share

    def dx(U):
        return height_um * np.exp(-0.5 * ((U[:, 0] - x0) / width_mm) ** 2)

    n = (rec.X2_mm - rec.X1_mm) / np.linalg.norm(rec.X2_mm - rec.X1_mm, axis=1)[:, None]
    err_um = n[:, 0] * (dx(U2) - dx(U1))
    rec = dataclasses.replace(rec, measured_mm=rec.measured_mm + err_um / 1000.0, N1=None, N2=None)
    return rec, model


def test_a_localized_bump_no_named_effect_explains_is_the_discrepancy():
    rec, model = bumped(seed=11, height_um=4.0, width_mm=100.0)
    j = dg.diagnose(rec, model).to_json()
    assert j["mismatch"] is True and j["explained"] is False
    d = j["discrepancy"]
    assert d["chosen"] is True and d["p_adjusted"] < j["alpha"]
    assert d["chi2_after"] < 0.5 * j["chi2_after"] and d["dof_after"] == j["dof_after"] - d["df"]
    # the bump moves x: the largest change is on a length along x, of the bump's size
    assert d["axis"] == "x" and d["record"].startswith("X-") and 2.0 < d["size_um"] < 6.0


def test_a_named_effect_that_explains_leaves_no_discrepancy():
    L, model = iso()
    rec = sm.simulate(L, MPE1, {"squareness_xy": 12 * u_effect(L, model, "squareness_xy")}, seed=3)
    j = dg.diagnose(rec, model).to_json()
    assert [e["name"] for e in j["effects"]] == ["squareness_xy"] and j["explained"] is True
    assert j["discrepancy"] is None


def test_pure_noise_has_no_discrepancy():
    L, model = iso()
    j = dg.diagnose(sm.simulate(L, MPE1, {}, seed=4), model).to_json()
    assert j["mismatch"] is False and j["discrepancy"] is None


def test_a_sinusoid_across_x_and_y_on_a_ball_plate_is_the_discrepancy_and_not_a_noise_level():
    """Point records: the y coordinate moved by 3 sin(2 pi (u_x/500 + u_y/700)) µm.  With no
    named effect the rest looks like a larger noise; the field, judged by the F-test, is a
    structure: chosen, the noise scale withdrawn, the rest explained, the size about 3 µm in y.
    (The size is the largest change of the fitted records, so it sits above the planted 2.98 µm
    peak: 3.33 ± 0.15 µm over seeds 0-19; the bounds are that spread ±4.5 sd, rounded.)"""
    L = sm.layout("ballplate", ONE)
    rec = sm.simulate(L, MPE1, {}, seed=5)

    def wave(U):
        d = np.zeros_like(U)
        d[:, 1] = 3.0 * np.sin(2 * np.pi * (U[:, 0] / 500.0 + U[:, 1] / 700.0))
        return d

    j = dg.diagnose(sm.plant_field(rec, wave), dg.Model(MPE1, ONE, True)).to_json()
    d = j["discrepancy"]
    assert j["mismatch"] is True and j["explained"] is False and j["effects"] == []
    assert d["chosen"] is True and d["test"] == "F" and j["noise_scale"] is None
    assert d["explained"] is True and d["axis"] == "y" and 2.6 < d["size_um"] < 4.0
