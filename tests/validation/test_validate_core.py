"""The validation core (xlfuncs/validation.py): E_n and its parts, the count against the claimed
coverage (binomial, and drawn with the rows' correlation), the structure and the verdict with its
cause, on hand-made rows and on a few simulated validation sets with known truth (the rates over
200 sets are bench/validate_rates.py's)."""

import math

import numpy as np
import pytest

from cmmwb.xlfuncs import validation as va
from cmmwb.xlfuncs import validation_sets as vsm
from cmmwb.xlfuncs.locator.model import Model
from cmmwb.xlfuncs.model import MPE1


def rows(dev_um, U=1.0, U_cal=0.5, k=2.0, k_cal=2.0, labels=None, y_cal=None, workpiece="W"):
    n = len(dev_um)
    y_cal = np.full(n, 100.0) if y_cal is None else np.asarray(y_cal, float)
    return va.Rows(tuple(labels or [f"c{i}" for i in range(n)]), (workpiece,) * n, ("1",) * n,
                   y_cal + 1e-3 * np.asarray(dev_um, float), np.ones(n, int), np.full(n, np.nan), y_cal,
                   np.full(n, U_cal), np.full(n, k_cal), np.full(n, U), np.full(n, k), np.full(n, 1000.0),
                   ("mm",) * n, ("µm",) * n, tuple(range(2, n + 2)))


def test_E_n_is_the_deviation_over_the_combined_expanded_uncertainty():
    r = rows([0.7])
    assert r.deviation[0] == pytest.approx(0.7, rel=1e-9)
    assert r.U_c[0] == pytest.approx(math.sqrt(1.0 + 0.25), rel=1e-15)
    assert r.E_n[0] == pytest.approx(0.7 / math.sqrt(1.25), rel=1e-9)
    # k = k_cal = 2: the claimed coverage is that of +-2 standard deviations
    assert r.claimed[0] == pytest.approx(0.9544997361036416, rel=1e-14)
    # k = 3 for the model, 2 for the certificate: U_c/u_c = sqrt(9 u^2 + 4 u_cal^2)/sqrt(u^2 + u_cal^2)
    r3 = rows([0.0], U=1.5, U_cal=0.5, k=3.0)
    e = math.sqrt(1.5**2 + 0.25) / math.sqrt(0.25 + 0.0625)
    assert r3.claimed[0] == pytest.approx(math.erf(e / math.sqrt(2)), rel=1e-14)


def test_the_binomial_tail_is_scipys():
    from scipy.stats import binom

    for k, n, p in ((45, 50, 0.9545), (0, 10, 0.9545), (300, 300, 0.9), (17, 40, 0.5), (800, 856, 0.9545)):
        assert va.binomial_cdf(k, n, p) == pytest.approx(binom.cdf(k, n, p), rel=1e-11, abs=1e-300)


def test_ten_fully_correlated_rows_outside_their_U_are_one_unlucky_draw_not_ten():
    """One draw of a shared error puts all ten rows outside together: the binomial count calls
    that impossible (p ~ 1e-13); with the rows' correlation its probability is that of one row,
    1 - 0.9545."""
    r = rows([1.2] * 10)
    assert int(np.sum(r.E_n <= 1)) == 0
    c = va.count_test(r, np.ones((10, 10)))
    assert c.p_low_binomial < 1e-12
    assert abs(c.p_low_correlated - (1 - 0.9545)) < 0.006      # 10,000 draws: sd 0.002
    assert "consistent with the coverage claimed" in c.words(0.01)


def test_too_few_rows_within_their_U_is_said_and_decided():
    rng = np.random.default_rng(2)
    r = rows(rng.normal(scale=1.0, size=60))          # u_c = 0.56 claimed, 1.0 true: U too small
    v = va.validate(r)
    assert not v.holds and v.verdict == "the model does not hold"
    assert v.count.p_low < 0.005 and "too small" in v.count.words(0.01)
    assert v.causes and v.next_step
    rng = np.random.default_rng(3)
    ok = va.validate(rows(rng.normal(scale=math.sqrt(0.25 + 0.0625), size=60)))
    assert ok.holds and ok.causes == [] and ok.next_step.startswith("none")


def test_a_scale_error_in_rows_without_probed_points_is_named_by_the_slope():
    y_cal = np.linspace(10.0, 500.0, 12)
    rng = np.random.default_rng(4)
    dev = 8.0e-3 * y_cal + rng.normal(scale=0.2, size=12)     # 8 µm/m
    v = va.validate(rows(dev, U=0.8, U_cal=0.2, y_cal=y_cal))
    assert not v.holds
    c = v.causes[0]
    assert c["kind"] == "scale" and abs(c["slope_um_per_m"] - 8.0) < 3 * c["u_um_per_m"]


@pytest.fixture(scope="module")
def plate():
    vs = vsm.build(("ballplate",))
    return vs, vsm.model_U(vs, MPE1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_right_model_holds_on_a_ball_plate(plate, seed):
    vs, U = plate
    rows_, geo = vsm.rows_of(vs, vsm.measure(vs, MPE1, {}, seed=seed), U)
    v = va.validate(rows_, geo, Model(MPE1, vsm.DEFAULT_PROBES, True))
    assert v.holds, va.summary(v)
    assert v.corr_known and v.diagnosis is not None and v.diagnosis.prep.rec.n == 300   # the runs merged


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_planted_squareness_is_found_and_named_on_a_ball_plate(plate, seed):
    vs, U = plate
    rows_, geo = vsm.rows_of(vs, vsm.measure(vs, MPE1, {"squareness_xy": 20.0}, seed=seed), U)
    v = va.validate(rows_, geo, Model(MPE1, vsm.DEFAULT_PROBES, True))
    assert not v.holds
    c = v.causes[0]
    assert c["kind"] == "effect" and c["name"] == "squareness_xy"
    assert abs(c["estimate"] - 20.0) < 3 * c["u"]
    assert "compensate" in v.next_step


def test_the_model_U_of_a_length_is_k_times_the_pointcloud_u_of_its_two_points():
    """The core's U of a ball-plate distance is 2 u(d) with u(d) of Forbes 2025 eq. (29), as the
    pointcloud kind computes it for the same two points (xlfuncs.pointcloud.distance_components)."""
    from cmmwb.xlfuncs import pointcloud as pc

    vs = vsm.build(("ballplate",))
    U = vsm.model_U(vs, MPE1)
    cloud = pc.PointCloud(vs.X, vs.N, vs.k, vs.probes)
    for c in vs.lengths[:40:7]:
        u = pc.distance_components(cloud, MPE1, np.array([[c.i, c.j]]))["u_um"][0]
        assert U[c.label] == pytest.approx(2.0 * u, rel=1e-9)
