"""The locator's second-edition candidates (docs/recordings.md section 7): straightness of the
axes, orders 2 and 3 (ISO 230-1 names EYX ... EYZ), and reversal errors along x, y, z.

The simulator plants them with its own code (numpy's Legendre series, the sign of the approach);
the locator's sensitivities (xlfuncs/locator/effects.py) must agree with it and find them."""

import numpy as np
import pytest

from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import effects as fx
from cmmwb.xlfuncs.locator import simulate as sm

from tests.helpers.clouds import MPE1, ONE, PAIR


def planted_delta(L, planted: dict) -> np.ndarray:
    """The simulator's displacement (µm) of every probing of ``L`` by ``planted`` (no time, 20 °C)."""
    return sm.planted_probing(L, sm.check_effects(planted, L.probes), np.zeros(len(L.X)),
                              np.full(len(L.X), 20.0))


def found(j, name):
    (e,) = [e for e in j["effects"] if e["name"] == name]
    return e


def test_the_simulator_plants_a_straightness_as_legendre_polynomials_of_the_travel():
    """At the ends of the travel P2 = 1 and P3 = +-1: the y deviation is c2 + c3 at the far end of
    the x travel and c2 - c3 at the near end."""
    L = sm.layout("ballplate", PAIR[:1])
    delta = planted_delta(L, {"EYX": [2.0, -0.5]})
    u = L.X[:, 0] - PAIR[0].offset_mm[0]
    assert delta[np.argmax(u), 1] == pytest.approx(2.0 - 0.5, abs=1e-12)
    assert delta[np.argmin(u), 1] == pytest.approx(2.0 + 0.5, abs=1e-12)
    assert np.all(delta[:, [0, 2]] == 0.0)


@pytest.mark.parametrize("name,value", [("EYX", [2.0, -0.5]), ("EXY", [1.0, 1.5]), ("reversal_x", 1.2),
                                        ("reversal_y", -0.8)])
def test_the_sensitivities_agree_with_the_simulator(name, value):
    """effects.columns times the planted parameters is the simulator's displacement of every
    coordinate (two independent codes of the same physics)."""
    L = sm.layout("holeplate", PAIR[:1], grid=3, passes=2)
    rec = sm.simulate(L, MPE1, {}, seed=1)
    prep = dg.prepare(rec, dg.Model(MPE1, PAIR[:1], True))
    cols = fx.columns(prep.design, name)
    beta = np.atleast_1d(np.asarray(value, dtype=float))
    delta = planted_delta(L, {name: value})
    # the design sees the measured ram positions, the simulator the nominal ones (µm apart)
    assert np.allclose(cols.X @ beta, prep.design.point_rows(delta), atol=1e-4 * np.max(np.abs(beta)))


def test_a_straightness_on_a_ball_plate_is_named_with_both_coefficients():
    L = sm.layout("ballplate", PAIR)
    rec = sm.simulate(L, MPE1, {"EYX": [3.0, -2.0]}, seed=3)
    j = dg.diagnose(rec, dg.Model(MPE1, PAIR, True)).to_json()
    assert j["effects"][0]["name"] == "EYX" and len(j["effects"]) == 1
    e = found(j, "EYX")
    assert e["unit"] == "um"
    for est, u, true in zip(e["estimate"], e["u"], (3.0, -2.0)):
        assert abs(est - true) < 3 * u
    assert j["explained"] is True


def test_a_straightness_needs_travel_of_its_carriage():
    """A 2-D hole plate: the z carriage does not move, EXZ and EYZ are not identifiable and say why."""
    L = sm.layout("holeplate", PAIR[:1], passes=2)
    j = dg.diagnose(sm.simulate(L, MPE1, {}, seed=2), dg.Model(MPE1, PAIR[:1], True)).to_json()
    reasons = {x["name"]: x["reason"] for x in j["not_identifiable"]}
    assert "the Z carriage moves" in reasons["EXZ"] and "no travel" in reasons["EXZ"]
    assert j["mismatch"] is False and j["effects"] == []


def test_a_reversal_on_a_hole_plate_is_named_and_estimated():
    """Holes probed from both sides along y: the points approached along +y are shifted by +1 µm,
    those approached along -y by -1 µm."""
    L = sm.layout("holeplate", PAIR[:1], passes=2)
    rec = sm.simulate(L, MPE1, {"reversal_y": 1.0}, seed=3)
    j = dg.diagnose(rec, dg.Model(MPE1, PAIR[:1], True)).to_json()
    assert [e["name"] for e in j["effects"]] == ["reversal_y"]
    e = found(j, "reversal_y")
    assert abs(e["estimate"] - 1.0) < 3 * e["u"] and e["u"] < 0.1


def test_a_reversal_needs_points_approached_from_both_sides():
    """Four spheres probed from above: every point is approached downwards along z."""
    L = sm.layout("spheres", PAIR)
    j = dg.diagnose(sm.simulate(L, MPE1, {}, seed=4), dg.Model(MPE1, PAIR, True)).to_json()
    reasons = {x["name"]: x["reason"] for x in j["not_identifiable"]}
    assert "from both sides" in reasons["reversal_z"]


def test_a_reversal_needs_normals():
    L = sm.layout("ballplate", PAIR)
    j = dg.diagnose(sm.simulate(L, MPE1, {}, seed=4), dg.Model(MPE1, PAIR, True)).to_json()
    reasons = {x["name"]: x["reason"] for x in j["not_identifiable"]}
    assert reasons["reversal_x"].startswith("needs normals")


def test_a_reversal_in_lengths_probed_from_both_sides():
    """ISO 10360-2 lengths with two probes: bidirectional lengths see twice the reversal."""
    L = sm.layout("iso10360", PAIR)
    rec = sm.simulate(L, MPE1, {"reversal_x": 1.5}, seed=17)
    j = dg.diagnose(rec, dg.Model(MPE1, PAIR, True)).to_json()
    e = found(j, "reversal_x")
    assert j["effects"][0]["name"] == "reversal_x" and abs(e["estimate"] - 1.5) < 3 * e["u"]


def test_simulate_takes_a_straightness_as_two_coefficients(tmp_path):
    from cmmwb.generator.cli.simulate import parse_effect
    from cmmwb.generator.errors import InputError

    assert parse_effect("EYX=2,-1.5", PAIR) == ("EYX", [2.0, -1.5])
    with pytest.raises(InputError, match="expected 2 numbers"):
        parse_effect("EYX=2", PAIR)


# -- thermal gradient: an expansion-coefficient error varying linearly along an axis ------------

def bump_T(L):
    """The room warms up by 3 K and cools again over the session."""
    return 20.0 + 3.0 * np.sin(np.pi * L.time_s / L.time_s.max())


def test_a_thermal_gradient_of_points_is_named_first_within_3u():
    """Ball plate measured four times while the temperature goes up and down."""
    L = sm.layout("ballplate", PAIR[:1], grid=3, passes=4)
    rec = sm.simulate(L, MPE1, {"thermal_gradient_y": 15.0}, seed=17, temperature_C=bump_T(L))
    j = dg.diagnose(rec, dg.Model(MPE1, PAIR[:1], True)).to_json()
    first = j["effects"][0]
    assert first["name"] == "thermal_gradient_y" and first["unit"] == "ppm/K/m"
    assert abs(first["estimate"] - 15.0) <= 3 * first["u"]


def test_a_thermal_gradient_of_lengths_is_named_first_within_3u():
    L = sm.layout("stepgauge", PAIR[:1], steps=8)
    rec = sm.simulate(L, MPE1, {"thermal_gradient_y": 150.0}, seed=17, temperature_C=bump_T(L))
    j = dg.diagnose(rec, dg.Model(MPE1, PAIR[:1], True)).to_json()
    first = j["effects"][0]
    assert first["name"] == "thermal_gradient_y" and abs(first["estimate"] - 150.0) <= 3 * first["u"]


def test_a_thermal_gradient_needs_temperatures_that_vary():
    L = sm.layout("ballplate", PAIR[:1], grid=3)
    none = dg.diagnose(sm.simulate(L, MPE1, {}, seed=3), dg.Model(MPE1, PAIR[:1], True)).to_json()
    const = dg.diagnose(sm.simulate(L, MPE1, {}, seed=3, temperature_C=21.0), dg.Model(MPE1, PAIR[:1], True)).to_json()
    reason = lambda j: {x["name"]: x["reason"] for x in j["not_identifiable"]}["thermal_gradient_x"]
    assert reason(none) == "needs temperature_C (absent from the records)"
    assert reason(const).startswith("temperature_C is the same for every record")


def test_planting_a_thermal_gradient_without_temperatures_is_refused():
    from cmmwb.xlfuncs.errors import ModelError

    with pytest.raises(ModelError, match="thermal_gradient_x needs temperatures"):
        sm.simulate(sm.layout("ballplate", PAIR[:1], grid=3), MPE1, {"thermal_gradient_x": 5.0}, seed=1)


# -- probe lobing: the radius depending on the approach direction around the stylus axis --------

LOBES = [0.8, -0.5, 0.6, 0.0, 0.3, 0.4]          # c2, s2, c3, s3, c4, s4 (µm)


def test_the_lobing_sensitivity_agrees_with_the_simulator():
    """effects: polynomials of (nx, ny)/|n_xy|; simulator: cos and sin of arctan2 (independent)."""
    L = sm.layout("spheres", PAIR)
    prep = dg.prepare(sm.simulate(L, MPE1, {}, seed=1), dg.Model(MPE1, PAIR, True))
    cols = fx.columns(prep.design, "probe_lobing")
    beta = np.r_[LOBES, np.zeros(6)]                  # P1 lobed, P2 not
    delta = planted_delta(L, {"probe_lobing": {"P1": LOBES}})
    assert cols.labels[:2] == ["P1.c2", "P1.s2"] and len(cols.labels) == 12
    assert np.allclose(cols.X @ beta, prep.design.point_rows(delta), atol=1e-6)


def test_probe_lobing_on_spheres_is_named_with_its_harmonics():
    L = sm.layout("spheres", PAIR)
    rec = sm.simulate(L, MPE1, {"probe_lobing": {"P1": LOBES}}, seed=3)
    j = dg.diagnose(rec, dg.Model(MPE1, PAIR, True)).to_json()
    assert [e["name"] for e in j["effects"]] == ["probe_lobing"]
    e = found(j, "probe_lobing")
    for est, u, true in zip(e["estimate"], e["u"], LOBES + [0.0] * 6):
        assert abs(est - true) < 3 * u


def test_probe_lobing_needs_normals():
    L = sm.layout("ballplate", PAIR)
    j = dg.diagnose(sm.simulate(L, MPE1, {}, seed=4), dg.Model(MPE1, PAIR, True)).to_json()
    reasons = {x["name"]: x["reason"] for x in j["not_identifiable"]}
    assert reasons["probe_lobing"].startswith("needs normals")


def test_probe_lobing_seen_from_four_directions_only_is_a_probe_radius_error():
    """Holes probed at four points: cos 4 phi is 1 at every point, the same as a radius error (a
    2 µm radius error planted, so that the search runs and reports its look-alikes)."""
    L = sm.layout("holeplate", PAIR[:1], passes=2)
    j = dg.diagnose(sm.simulate(L, MPE1, {"probe_radius": 2.0}, seed=4), dg.Model(MPE1, PAIR[:1], True)).to_json()
    assert [e["name"] for e in j["effects"]] == ["probe_radius"]
    item = next(x for x in j["not_identifiable"] if x["name"] == "probe_lobing")
    assert item["aliased_with"] == "probe_radius"


# -- periodic errors: a sine of the travel, its period found by a scan -----------------------------

@pytest.mark.parametrize("name", ["periodic_x", "periodic_y"])
def test_the_periodic_sensitivity_agrees_with_the_simulator(name):
    """a sin + b cos of 2 pi t/P about the middle of the travel (effects.py) against the
    simulator's Re((b - i a) exp(i 2 pi t/P)) (simulate.py)."""
    L = sm.layout("holeplate", PAIR[:1], passes=2)
    rec = sm.simulate(L, MPE1, {}, seed=1)
    prep = dg.prepare(rec, dg.Model(MPE1, PAIR[:1], True))
    cols = fx.columns(prep.design, name, 97.0)
    delta = planted_delta(L, {name: [1.3, -0.7, 97.0]})
    assert cols.labels == ["a", "b"] and cols.period_mm == 97.0
    assert np.allclose(cols.X @ [1.3, -0.7], prep.design.point_rows(delta), atol=1e-4)


def test_the_period_column_is_the_derivative_of_the_sine():
    """effects.period_column against a central difference of periodic_columns in the period."""
    L = sm.layout("stepgauge", PAIR[:1])
    prep = dg.prepare(sm.simulate(L, MPE1, {}, seed=1), dg.Model(MPE1, PAIR[:1], True))
    a, b, P, h = 0.8, -0.3, 71.0, 1e-4
    plus, minus = (fx.columns(prep.design, "periodic_x", P + s * h).X @ [a, b] for s in (1, -1))
    assert np.allclose(fx.period_column(prep.design, "periodic_x", P, a, b), (plus - minus) / (2 * h),
                       rtol=1e-6, atol=1e-9)


def test_a_periodic_error_on_a_step_gauge_is_named_with_its_period():
    """1 µm at 72 mm pitch along x on step gauges along x, y and the xy diagonal: named first, a,
    b and the period within 3u, the p-value carrying the look-elsewhere factor of the scan."""
    L = sm.layout("stepgauge", ONE)
    rec = sm.simulate(L, MPE1, {"periodic_x": [0.6, -0.8, 72.0]}, seed=5)
    j = dg.diagnose(rec, dg.Model(MPE1, ONE, True)).to_json()
    assert [e["name"] for e in j["effects"]] == ["periodic_x"]
    e = found(j, "periodic_x")
    for est, u, true in zip(e["estimate"], e["u"], [0.6, -0.8]):
        assert abs(est - true) < 3 * u
    assert abs(e["period_mm"] - 72.0) < 3 * e["u_period_mm"] and e["u_period_mm"] < 2.0
    periods, M = fx.period_grid(dg.prepare(rec, dg.Model(MPE1, ONE, True)).design, 0)
    assert e["periods_searched"] == M > 1 and periods[0] > periods[-1]
    # the step's p-value is the chi-square tail (df 2) times M
    assert e["log10_p_value"] == pytest.approx(
        np.log10(M) + dg.chi2_logsf(e["delta_chi2"], 2) / np.log(10), abs=1e-9)


@pytest.mark.parametrize("layout,probes", [("iso10360", ONE), ("ballplate", PAIR[:1])])
def test_a_periodic_error_needs_the_axis_sampled_densely(layout, probes):
    """ISO 10360-2 lengths and a ball plate see each axis at a few positions, 40-70 mm apart: a
    sine through them fits a bump as well, so no period is identifiable (docs/diagnose.md
    section 6: four probings per cycle at the widest gap, three cycles over the travel)."""
    L = sm.layout(layout, probes)
    j = dg.diagnose(sm.simulate(L, MPE1, {}, seed=4), dg.Model(MPE1, probes, True)).to_json()
    reasons = {x["name"]: x["reason"] for x in j["not_identifiable"]}
    for ax in "xy":
        assert "probings per cycle at the widest gap" in reasons[f"periodic_{ax}"]
        assert "a step gauge or a scan along " + ax in reasons[f"periodic_{ax}"]


def test_null_step_gauges_do_not_name_a_periodic_error():
    """The scan looks at many periods; with its look-elsewhere factor and the naming level
    alpha/100, records that agree with the simulation name no periodic error."""
    L = sm.layout("stepgauge", PAIR)
    model = dg.Model(MPE1, PAIR, True)
    for seed in range(12):
        j = dg.diagnose(sm.simulate(L, MPE1, {}, seed=100 + seed), model).to_json()
        assert not [e for e in j["effects"] if e["name"].startswith("periodic")], seed


def test_simulate_takes_a_periodic_error_as_a_b_and_period(tmp_path):
    from cmmwb.generator.cli.simulate import parse_effect
    from cmmwb.generator.errors import InputError

    assert parse_effect("periodic_y=0.5,-0.2,40", PAIR) == ("periodic_y", [0.5, -0.2, 40.0])
    with pytest.raises(InputError, match="expected 3 numbers"):
        parse_effect("periodic_y=0.5,-0.2", PAIR)
    with pytest.raises(InputError, match="period must be above 0 mm"):
        parse_effect("periodic_y=0.5,-0.2,0", PAIR)
