"""REML of the six factors' hyper-parameters (xlfuncs/calibrate.py): the closed-form gradient and
kernel derivatives, identifiability, and the demo data's hyper-parameters reproduced."""

import math

import numpy as np
import pytest

from cmmwb.xlfuncs import calibrate as cb
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs import reml
from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.model import length_covariance

from tests.helpers.clouds import MPE1, ONE, PAIR, THREE


def prepared(layout, probes, planted=None, seed=1, **kw):
    rec = sm.simulate(sm.layout(layout, probes, **kw), MPE1, planted or {}, seed=seed)
    return dg.prepare(rec, dg.Model(MPE1, probes, True), False)


def values(p):
    return {n: float(getattr(p, n)) for n in reml.NAMES}


@pytest.mark.parametrize("layout,probes,kw", [("iso10360", THREE, {"repeats": 1}),
                                               ("spheres", PAIR, {}),
                                               ("ballplate", PAIR, {"grid": 3})])
def test_the_closed_form_gradient_is_the_derivative_of_the_reml_likelihood(layout, probes, kw):
    s = reml.record_set(prepared(layout, probes, **kw))
    v = values(MPE1)
    free = list(reml.NAMES)
    t = reml.reml_terms([s], v, free)
    h = 1e-5
    for k, name in enumerate(free):
        up, dn = dict(v), dict(v)
        up[name] *= math.exp(h)
        dn[name] *= math.exp(-h)
        fd = (reml.reml_terms([s], up, [], fisher=False).loglik - reml.reml_terms([s], dn, [], fisher=False).loglik) / (2 * h)
        assert abs(t.grad[k] - fd) <= 1e-5 * max(1.0, abs(fd)), (name, t.grad[k], fd)


def test_the_kernel_derivative_of_length_records_is_d_dlog_lambda():
    prep = prepared("iso10360", THREE, repeats=1)
    I, J = prep.ends
    cloud = reml.DenseRecordCovariance(prep).cloud
    d = length_covariance(cloud, MPE1, I, J, components=True, d_log_lambda=True)
    h = 1e-6
    for f, lam in (("ET", "lambda_ET_mm"), ("ER", "lambda_ER_mm"), ("P", "lambda_P")):
        from dataclasses import replace

        up = length_covariance(cloud, replace(MPE1, **{lam: getattr(MPE1, lam) * math.exp(h)}), I, J, components=True)
        dn = length_covariance(cloud, replace(MPE1, **{lam: getattr(MPE1, lam) * math.exp(-h)}), I, J, components=True)
        fd = (up[f] - dn[f]) / (2 * h)
        assert np.max(np.abs(d[f] - fd)) <= 1e-6 * max(np.max(np.abs(fd)), 1e-12), f


def test_the_kernel_derivative_of_point_records_is_d_dlog_lambda():
    from dataclasses import replace

    prep = prepared("spheres", PAIR)
    cloud = reml.DenseRecordCovariance(prep).cloud
    d = pc.V_X_components(cloud, MPE1, d_log_lambda=True)
    h = 1e-6
    for f, lam in (("ET", "lambda_ET_mm"), ("ER", "lambda_ER_mm"), ("P", "lambda_P")):
        up = pc.V_X_components(cloud, replace(MPE1, **{lam: getattr(MPE1, lam) * math.exp(h)}))[f]
        dn = pc.V_X_components(cloud, replace(MPE1, **{lam: getattr(MPE1, lam) * math.exp(-h)}))[f]
        fd = (up - dn) / (2 * h)
        assert np.max(np.abs(d[f] - fd)) <= 1e-6 * np.max(np.abs(fd)), f


def test_the_record_covariance_is_the_one_diagnose_uses():
    for prep in (prepared("iso10360", THREE, repeats=1), prepared("ballplate", PAIR, grid=3)):
        C, _ = reml.record_covariance(prep).evaluate(values(MPE1), [])
        assert np.max(np.abs(C - prep.C)) <= 1e-12 * np.max(np.abs(prep.C))


def test_sigma_ER_with_one_probe_offset_is_reported_not_identifiable():
    s = reml.record_set(prepared("iso10360", ONE))
    cal = cb.calibrate([s], MPE1)
    e = cal.estimates["sigma_ER_urad"]
    assert e.status == "not identifiable" and "one probe offset" in e.reason
    assert "probe offsets" in e.advice
    assert e.value == MPE1.sigma_ER_urad          # held at the task's value
    pq = cal.estimates["sigma_PQ_um"]
    assert pq.status == "not identifiable" and "one probe" in pq.reason


def test_with_several_probe_offsets_on_a_ball_plate_PQ_and_ET_are_estimated():
    s = reml.record_set(prepared("ballplate", PAIR, passes=4, seed=3))
    cal = cb.calibrate([s], MPE1)
    for name in ("sigma_R_um", "sigma_PQ_um", "sigma_ET_um"):
        assert cal.estimates[name].status == "estimated", (name, cal.estimates[name].reason)
    # the fit improves the REML likelihood and every u is finite
    assert cal.loglik >= cal.loglik_start - 1e-9
    assert all(math.isfinite(cal.estimates[n].u) for n in cal.free)


@pytest.mark.parametrize("planted,seed", [({"squareness_xy": 9.0}, 3), ({"EBX": 150.0}, 5)])
def test_the_demo_data_reproduce_the_simulations_hyper_parameters_within_u(planted, seed):
    """The two cases of `cmmwb demo` (generator/diagnosis/run.py demo): with the named effect as a
    fixed effect, every estimated hyper-parameter lies within one u of the value simulated."""
    from cmmwb.generator.diagnosis.run import DEMO_PROBES

    rec = sm.simulate(sm.iso10360(DEMO_PROBES), MPE1, planted, seed=seed, temperature_C=20.0)
    prep = dg.prepare(rec, dg.Model(MPE1, DEMO_PROBES, True), False)
    diag = dg.diagnose_prepared(prep)
    assert diag.chosen
    s = reml.RecordSet("demo", prep, diag.X_sel, [str(lb) for lb in diag.sel_labels], reml.record_covariance(prep))
    cal = cb.calibrate([s], MPE1)
    assert cal.free
    for name in cal.free:
        e = cal.estimates[name]
        assert abs(e.value - getattr(MPE1, name)) <= e.u, (name, e.value, e.u)


def test_a_length_scale_beyond_the_travel_is_reported_as_such():
    from dataclasses import replace

    far = replace(MPE1, lambda_ET_mm=5000.0)
    rec = sm.simulate(sm.layout("ballplate", PAIR), far, {}, seed=2)
    prep = dg.prepare(rec, dg.Model(far, PAIR, True), False)
    cal = cb.calibrate([reml.record_set(prep)], far)
    for name in ("sigma_ET_um", "lambda_ET_mm"):
        e = cal.estimates[name]
        assert e.status == "not identifiable" and "beyond the travel" in e.reason, (name, e.reason)


def test_feeding_back_a_scale_error_compensated_or_as_a_factor():
    from cmmwb.xlfuncs import compensation as cp

    found = [cp.Finding("scale", [8.0], [0.5], "um/m"), cp.Finding("EBX", [150.0], [20.0], "urad/m")]
    comp, changes, notes = cp.feed_back(MPE1, found, "compensate")
    assert comp.sigma_S_ppm == 0.5 and comp.sigma_Sa_ppm == MPE1.sigma_Sa_ppm
    assert [c.parameter for c in changes] == ["sigma_S_ppm"]
    assert any(n.startswith("EBX compensated") for n in notes)        # outside the six factors
    fac, _, _ = cp.feed_back(MPE1, found[:1], "factor")
    assert math.isclose(fac.sigma_S_ppm, math.sqrt(0.7**2 + 8.0**2 + 0.5**2), rel_tol=1e-12)
    with pytest.raises(Exception, match="cannot be added as a factor"):
        cp.feed_back(MPE1, found, "factor")
    # one of three per-axis scales corrected: the factor keeps its spread (y and z still carry it)
    part, changes, _ = cp.feed_back(MPE1, [cp.Finding("scale_x", [3.0], [0.2], "um/m")], "compensate")
    assert part.sigma_Sa_ppm == MPE1.sigma_Sa_ppm and "keeps its spread" in changes[0].how
    assert cp.absorbed(["scale_x", "scale_y"]) == set() and cp.absorbed(["scale"]) == {"sigma_S_ppm"}


def two_peak_set(repeats, seed):
    """ISO 10360-2 lengths with the three styli of `THREE`, a machine drawn from MPE1 (seeded):
    sets whose REML likelihood has two peaks (found by scanning seeds, /bench of issue 36)."""
    return [reml.record_set(prepared("iso10360", THREE, seed=seed, repeats=repeats), "iso")]


def test_a_fit_that_stops_on_the_lower_of_two_peaks_moves_to_the_higher_one():
    """Six repeats, seed 3: four GP hyper-parameters free (sigma_ET, lambda_ET, sigma_ER, lambda_ER)
    and sigma_R, sigma_P. From the task's values Fisher scoring stops on a peak with lambda_ET
    237 mm (log-likelihood -91.895); a start at a quarter of it climbs to lambda_ET 61 mm, 1.377
    log-units higher. The fit reports the higher peak and says the likelihood has two."""
    sets = two_peak_set(6, 3)
    lower = cb.calibrate(sets, MPE1, other_starts=False)
    assert set(lower.free) >= {"sigma_ET_um", "lambda_ET_mm", "sigma_ER_urad", "lambda_ER_mm"}
    assert abs(lower.estimates["lambda_ET_mm"].value - 236.8) <= 0.5 and lower.multimodal is None
    cal = cb.calibrate(sets, MPE1)
    assert abs(cal.estimates["lambda_ET_mm"].value - 61.45) <= 0.5
    assert abs(cal.estimates["sigma_ET_um"].value - 0.1497) <= 0.001
    assert abs((cal.loglik - lower.loglik) - 1.377) <= 0.002
    assert cal.peaks[0].loglik == cal.loglik and len(cal.peaks) >= 2
    other = min(cal.peaks[1:], key=lambda p: abs(p.values["lambda_ET_mm"] - 236.8))
    assert abs(other.values["lambda_ET_mm"] - 236.8) <= 0.5 and other.found_by == "the task's values"
    text = cal.multimodal
    assert text.startswith(f"The REML likelihood has {len(cal.peaks)} peaks; the fit is the highest")
    assert "lambda_ET_mm 61.5 vs 237 mm" in text and "1.377 lower" in text
    assert "do not rule it out" in text        # 2 x 1.377 < 3.84: the records prefer, not prove
    assert cal.to_json()["multimodal"] == text and len(cal.to_json()["peaks"]) == len(cal.peaks)


def test_a_profile_that_reaches_higher_moves_the_fit_there():
    """Three repeats, seed 10 (sigma_R, sigma_ER, lambda_ER free): without the other starts the fit
    stops at lambda_ER 310 mm; the profile of sigma_R reaches a point 0.64 log-units higher, the fit
    is repeated from there (lambda_ER 42 mm) and both peaks are reported; the profiles are then
    those of the higher peak (none above it)."""
    from cmmwb.xlfuncs import calibration_checks as checks

    lower = cb.calibrate(two_peak_set(3, 10), MPE1, other_starts=False)
    assert abs(lower.estimates["lambda_ER_mm"].value - 310.2) <= 0.5 and len(lower.peaks) == 1
    cal, profiles = checks.profiles_at_maximum(lower)
    assert cal is not lower and abs((cal.loglik - lower.loglik) - 0.644) <= 0.002
    assert abs(cal.estimates["lambda_ER_mm"].value - 41.8) <= 0.5
    assert cal.peaks[0].found_by.startswith("the profile of ")
    assert any(abs(p.values["lambda_ER_mm"] - 310.2) <= 0.5 for p in cal.peaks[1:])
    assert [p["name"] for p in profiles] == cal.free
    assert max(max(p["delta_loglik"]) for p in profiles) <= cb.PEAK_GAIN


def test_a_single_peak_is_not_called_multimodal():
    cal = cb.calibrate(two_peak_set(3, 0), MPE1)
    assert len(cal.peaks) == 1 and cal.multimodal is None and cal.to_json()["multimodal"] is None
