"""The workpiece's temperature, the factor W (docs/workpiece.md): a length's u_W is
L sqrt((T - 20)^2 u^2(alpha) + alpha^2 u^2(T)) on every path of the core, the uncorrected expansion is
carried in quadrature, and on the simulated plate every characteristic's u with W agrees with a
JCGM 101 Monte Carlo that perturbs alpha and T (two significant digits), form characteristics
showing the small W share they should (u_W = u(eps) x the zone: a scale maps a plane to a plane)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import budget as bd
from cmmwb.xlfuncs import characteristics as ch
from cmmwb.xlfuncs import montecarlo as mc
from cmmwb.xlfuncs import plate as pl
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.locator.model import length_covariance
from cmmwb.xlfuncs.model import MPE1, Workpiece, workpiece_from_readings

from tests.helpers import close

#: the issue's shop floor: an aluminium housing (alpha = 23e-6/K, u = 1e-6/K) at 23.5 °C, u(T) = 0.3 K
HOUSING = Workpiece(alpha_ppm_per_K=23.0, T_degC=23.5, fixture_mm=(40.0, 80.0, 0.0))
U = {"u_alpha_ppm_per_K": 1.0, "u_T_K": 0.3}


def bores(part=HOUSING, params=MPE1) -> tuple[pc.PointCloud, pc.Parameters]:
    """Two bore axes' points 400 mm apart (x), and a few more, on one probe."""
    X = np.array([[40.0, 80.0, 10.0], [440.0, 80.0, 10.0], [40.0, 150.0, 0.0], [300.0, 10.0, 30.0]])
    N = np.tile([0.0, 0.0, 1.0], (4, 1))
    cloud = pc.PointCloud(X, N, np.zeros(4, int), (pc.Probe("P1", (0.0, 0.0, -50.0)),), ("H1", "H2", "A", "B"),
                          workpiece=part)
    from dataclasses import replace
    return cloud, replace(params, **U)


def test_the_issue_numbers_a_400_mm_bore_distance():
    """u(alpha) over 3.5 K: 1.4 µm; u(T) = 0.3 K: 2.76 µm; together L u(eps) = 3.0948 µm."""
    terms = HOUSING.terms_ppm(1.0, 0.3)
    assert terms["alpha"] * 400 * 1e-3 == pytest.approx(1.4, rel=1e-12)
    assert terms["T"] * 400 * 1e-3 == pytest.approx(2.76, rel=1e-12)
    assert HOUSING.u_eps_ppm(1.0, 0.3) * 400e-3 == pytest.approx(400e-3 * math.sqrt(3.5**2 + 6.9**2), rel=1e-15)


def test_a_lengths_u_W_is_L_u_eps_on_every_path():
    cloud, params = bores()
    want = 400.0 * math.sqrt(3.5**2 + (23.0 * 0.3) ** 2) * 1e-3          # µm
    every = pc.distance_components(cloud, params)                          # the all-pairs kernel (d u(eps))
    given = pc.distance_components(cloud, params, np.array([[0, 1]]))     # the columns of V_W
    assert every["u_W_um"][0] == pytest.approx(want, rel=1e-14)
    assert given["u_W_um"][0] == pytest.approx(want, rel=1e-14)
    blocks = bl.pair_blocks(cloud, params, [[0, 1]], ("W",))["W"][0]
    assert math.sqrt(blocks[0, 0]) == pytest.approx(want, rel=1e-14)
    C = length_covariance(cloud, params, np.array([0]), np.array([1]), components=True)["W"]
    assert math.sqrt(C[0, 0]) == pytest.approx(want, rel=1e-14)
    V = pc.V_X_components(cloud, params)["W"]
    assert pc.distance_u_dense(V, cloud.X_mm, 0, 1) == pytest.approx(want, rel=1e-12)
    # the budget of Wojtyla/Plowucha: l = 400 mm as a point_point distance
    pts = {"H1": cloud.X_mm[0], "H2": cloud.X_mm[1]}
    d = bd.distance_budget(bd.specs_for("point_point", points_used={"from": "H1", "to": "H2"}), pts,
                           bd.MPE(3.0, 250.0, 0.577), part=bd.Part(HOUSING, **U))
    assert d.chosen.u_W_um == pytest.approx(want, rel=1e-14)
    assert d.u_um == pytest.approx(math.hypot(d.chosen.u_mpe_um, want), rel=1e-14)
    rows = {r["input"]: r for r in d.chosen.thermal}
    assert rows["alpha"]["sensitivity"] == pytest.approx(-400 * 3.5e-3, rel=1e-14)       # -l (T - 20)
    assert rows["T"]["sensitivity"] == pytest.approx(-400 * 23e-3, rel=1e-14)            # -l alpha


def test_the_fixture_point_cancels_in_distances_not_in_positions():
    from dataclasses import replace

    a, params = bores()
    b, _ = bores(replace(HOUSING, fixture_mm=(-500.0, 300.0, 90.0)))
    da, db = (pc.distance_components(c, params)["u_W_um"] for c in (a, b))
    assert np.allclose(da, db, rtol=1e-12, atol=0)
    Va, Vb = (pc.V_X_components(c, params)["W"] for c in (a, b))
    assert not np.allclose(np.diag(Va), np.diag(Vb))          # a point's own position moves with x0


def test_the_uncorrected_expansion_is_carried_in_quadrature():
    """No correction: b = alpha (T - 20) = 80.5e-6, u^2(eps) = b^2 + the corrected terms (RSSu);
    corrected with a nominal alpha 1e-6/K off: b = 3.5e-6."""
    from dataclasses import replace

    raw = replace(HOUSING, corrected=False)
    assert raw.bias_ppm() == pytest.approx(23.0 * 3.5, rel=1e-15)
    assert raw.u_eps_ppm(1.0, 0.3) == pytest.approx(math.hypot(HOUSING.u_eps_ppm(1.0, 0.3), 80.5), rel=1e-14)
    off = replace(HOUSING, alpha_corr_ppm_per_K=22.0)
    assert off.bias_ppm() == pytest.approx(3.5, rel=1e-15)
    cloud, params = bores(raw)
    d = pc.distance_components(cloud, params, np.array([[0, 1]]))
    assert d["u_W_um"][0] == pytest.approx(400e-3 * raw.u_eps_ppm(1.0, 0.3), rel=1e-14)


def test_a_temperature_difference_is_a_rectangular_spread_and_readings_give_it():
    wp = workpiece_from_readings([23.3, 23.7, 23.5], alpha_ppm_per_K=23.0)
    assert (wp.T_degC, wp.dT_K) == (pytest.approx(23.5, rel=1e-15), pytest.approx(0.4, rel=1e-12))
    assert wp.terms_ppm(1.0, 0.3)["dT"] == pytest.approx(23.0 * 0.4 / math.sqrt(12), rel=1e-14)


def test_W_off_is_the_machine_alone():
    from dataclasses import replace

    on, params = bores()
    off, _ = bores(replace(HOUSING, enabled=False))
    none, _ = bores(None)
    d_off, d_none = (pc.distance_components(c, params) for c in (off, none))
    for k in d_none:
        assert np.array_equal(d_off[k], d_none[k]), k
    assert np.all(d_off["u_W_um"] == 0.0)
    assert pc.distance_components(on, params)["u_W_um"][0] > 3.0


def test_bad_workpieces_say_what_is_wrong():
    with pytest.raises(ModelError, match="dT_K"):
        Workpiece(23.0, 23.5, dT_K=-1.0)
    with pytest.raises(ModelError, match="fixture_mm"):
        Workpiece(23.0, 23.5, fixture_mm=(0.0, float("nan"), 0.0))
    with pytest.raises(ModelError, match="temperatures"):
        pc.PointCloud(np.zeros((2, 3)), np.zeros((2, 3)), np.zeros(2, int), (pc.Probe("P"),), workpiece=HOUSING,
                      temperature_C=np.array([20.0]))


# -- Monte Carlo (JCGM 101) that perturbs alpha and T ---------------------------------------------

def test_distances_agree_with_a_monte_carlo_that_perturbs_alpha_and_T():
    cloud, params = bores()
    pairs = np.array([[0, 1], [0, 2], [2, 3]])
    direct = pc.distance_components(cloud, params, pairs)
    r = mc.distances(cloud, params, pairs, rng=np.random.default_rng(11), batch=20_000)
    assert r.converged
    for q in range(len(pairs)):
        assert abs(r.u[q] - direct["u_um"][q]) <= r.tolerance[q], (q, r.u[q], direct["u_um"][q])
        assert abs(r.components["W"][q] - direct["u_W_um"][q]) <= mc.numerical_tolerance(
            r.components["W"][q:q + 1], 2)[0]


PARAMS = pc.Parameters(sigma_R_um=0.2, sigma_S_ppm=0.7, sigma_Sa_ppm=0.8, sigma_Q_ppm=0.9,
                       sigma_PQ_um=0.2, sigma_ET_um=0.3, lambda_ET_mm=150, sigma_ER_urad=4.0,
                       lambda_ER_mm=350, sigma_P0_um=0.1, sigma_P_um=0.15, lambda_P=0.5,
                       u_alpha_ppm_per_K=1.0, u_T_K=0.5)
#: the plate of xlfuncs.plate in aluminium at 26 °C, 0.4 K across it, held at its corner: u(eps) 13 ppm
PLATE_PART = Workpiece(23.1, 26.0, fixture_mm=(0.0, 0.0, 0.0), dT_K=0.4)


@pytest.fixture(scope="module")
def plate_with_W():
    X, N, feats, frames, chars = pl.plate()
    cloud = pc.PointCloud(X, N, np.zeros(len(X), int), (pc.Probe("P1", (0.0, 0.0, -50.0)),), workpiece=PLATE_PART)
    V = pc.V_X_components(cloud, PARAMS)
    jf = ch.fit_features(X, N, feats)
    res = ch.evaluate(jf, frames, chars, V)
    return dict(frames=frames, chars=chars, cloud=cloud, jf=jf, res=res)


def test_every_characteristic_with_W_agrees_with_a_monte_carlo_that_perturbs_alpha_and_T(plate_with_W):
    """The plate's positions, flatness, distances, sizes, form and orientation with the part's
    temperature: every linearised u within the Monte Carlo's two significant digits (JCGM 101 7.9:
    |u - u_MC| <= delta; 46,000 draws with this seed), W drawn as the physical model (alpha and T
    drawn, the part expanded and corrected)."""
    p = plate_with_W
    res = p["res"]
    r = ch.monte_carlo(p["jf"], p["frames"], p["chars"], res, p["cloud"], PARAMS, rng=np.random.default_rng(5),
                       batch=2000)
    assert r.converged and np.all(2 * r.s_u <= r.tolerance)
    lin = np.array([x.u for x in res] + [x.u_margin_um for x in res if x.u_margin_um is not None])
    bad = [(n, a, b) for n, a, b, t in zip(r.names, lin, r.u, r.tolerance) if abs(a - b) > t]
    assert not bad
    by = {x.name: x for x in res}
    # W is visible where lengths are: the distance of the holes (40 mm: d u(eps), to the 1e-4 by which
    # the scale also moves the point of H1's tilted axis where the distance is taken) and the width
    u_eps = PLATE_PART.u_eps_ppm(1.0, 0.5)
    assert close(by["dist_H1_H2"].u_factors["W"], by["dist_H1_H2"].value * u_eps * 1e-3, rel=1e-3)
    assert by["width_B_D"].u_factors["W"] / by["width_B_D"].u > 0.5


def test_form_characteristics_show_the_small_W_share_they_should(plate_with_W):
    """A uniform scale maps a plane to a plane: a form zone scales with the part, u_W = u(eps) x zone
    (a few 1e-5 µm here), its share of u^2 below 1e-6."""
    u_eps = PLATE_PART.u_eps_ppm(1.0, 0.5)
    forms = [x for x in plate_with_W["res"] if x.spec.type in ("flatness", "straightness", "roundness", "cylindricity")]
    assert len(forms) >= 6
    for x in forms:
        zone_um = x.value * 1e3
        assert x.u_factors["W"] == pytest.approx(u_eps * 1e-6 * zone_um, rel=0.02, abs=1e-9), x.name
        assert (x.u_factors["W"] / x.u) ** 2 < 1e-6, x.name


def test_W_alone_in_a_monte_carlo_gives_each_characteristics_u_W(plate_with_W):
    """Only alpha and T drawn (the sampler's factor W alone; 28,000 draws with this seed), every
    feature refitted and every characteristic evaluated anew (minimum zones solved again): each
    characteristic's linearised u_W within the Monte Carlo's two significant digits, the form,
    orientation and parallelism ones (about 1e-4 µm: u(eps) x zone) as well as the sizes, the
    distance, the width and the positions (0.13 to 1.8 µm).  The angle (0: a scale keeps angles)
    and perp_H1_A (below 1e-8 µm) are left out: their Monte Carlo u is round-off."""
    p = plate_with_W
    keep = [i for i, x in enumerate(p["res"]) if x.u_factors["W"] > 1e-6]
    chars = [p["chars"][i] for i in keep]
    res = [p["res"][i] for i in keep]
    assert {c.type for c in chars} >= {"flatness", "straightness", "roundness", "cylindricity", "position",
                                       "distance", "diameter", "width", "perpendicularity", "parallelism"}
    r = ch.monte_carlo(p["jf"], p["frames"], chars, res, p["cloud"], PARAMS, rng=np.random.default_rng(7),
                       batch=2000, sampler=mc.PointCloudSampler(p["cloud"], PARAMS, factors=("W",)))
    assert r.converged
    for x, u_mc, t in zip(res, r.u, r.tolerance):
        assert abs(x.u_factors["W"] - u_mc) <= t, (x.name, x.u_factors["W"], u_mc, t)
        if x.spec.type in ("flatness", "straightness", "roundness", "cylindricity"):
            assert u_mc < 2e-4 and (u_mc / x.u) ** 2 < 1e-6, (x.name, u_mc, x.u)
