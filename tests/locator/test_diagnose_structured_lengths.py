"""The mismatch locator on length records with the structured covariance C = D + U U^T
(xlfuncs.locator.structured_lengths: never n x n, the same GP factors as point records) gives the dense
path's chi-square, p-values, choices, estimates and uncertainties to relative 1e-8; the operator
itself (C v, C^-1 v, log det C) equals the dense G V_X G^T."""

import numpy as np
import pytest

from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import model as locator_model
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator import structured_lengths as sl

from tests.helpers import max_rel_diff as rel
from tests.helpers.clouds import MPE1, PAIR

REL = 1e-8


MODEL = dg.Model(MPE1, PAIR, True)


@pytest.fixture(scope="module")
def iso():
    """ISO 10360-2 (7 positions x 5 lengths x 2 repeats, two probes) with a planted scale error
    of 3 ppm, diagnosed both ways."""
    rec = sm.simulate(sm.iso10360(PAIR, repeats=2), MPE1, {"scale": 3.0}, seed=3)
    return dg.diagnose(rec, MODEL, structured=True), dg.diagnose(rec, MODEL, structured=False)


@pytest.fixture(scope="module")
def stepgauge():
    """A step gauge in three positions: every length starts at the first face, one probing
    shared by 51 records (the R factor's shared columns)."""
    rec = sm.simulate(sm.stepgauge(PAIR), MPE1, {"scale_x": 2.0}, seed=5)
    return rec, dg.prepare(rec, MODEL, True), dg.prepare(rec, MODEL, False)


def test_the_operator_equals_the_dense_covariance(stepgauge):
    _rec, s, d = stepgauge
    assert isinstance(s.C, sl.LengthCovariance) and s.C.c_max == 51
    assert rel(s.C.dense(), d.C) <= 1e-10 or np.max(np.abs(s.C.dense() - d.C)) <= 1e-10 * np.max(np.abs(d.C))
    assert np.max(np.abs(s.C.diagonal() - np.diag(d.C))) <= 1e-10 * np.max(np.diag(d.C))


def test_matvec_solve_and_log_determinant_equal_the_dense_ones(stepgauge):
    _rec, s, d = stepgauge
    V = np.random.default_rng(0).normal(size=(s.C.n, 3))
    assert np.max(np.abs(s.C.matvec(V) - d.C @ V)) <= 1e-10 * np.max(np.abs(d.C @ V))
    x = np.linalg.solve(d.C, V)
    assert np.max(np.abs(s.C.solve(V) - x)) <= REL * np.max(np.abs(x))
    assert abs(s.C.logdet() - np.linalg.slogdet(d.C)[1]) <= REL * abs(np.linalg.slogdet(d.C)[1])


def test_the_stated_bound_is_small_and_covers_the_error(stepgauge):
    _rec, s, d = stepgauge
    err = np.linalg.norm(s.C.dense() - d.C, 2)
    assert err <= s.C.eps_C + 1e-12 * np.linalg.norm(d.C, 2)
    assert 0 < s.C.chi2_bound() <= 1e-6


def test_the_planted_effect_is_found_by_both_paths(iso):
    s, d = iso
    assert not isinstance(s.prep.C, np.ndarray) and s.whitener.mode == "structured"
    assert s.chosen == d.chosen == ["scale"]


def test_chi_square_and_p_values_equal_the_dense_path(iso):
    s, d = iso
    assert rel(s.chi2_before, d.chi2_before) <= REL
    assert rel(s.chi2_after, d.chi2_after) <= REL
    assert rel(s.logp_before, d.logp_before) <= REL
    assert rel(s.logp_after, d.logp_after) <= REL
    assert (s.dof_before, s.dof_after) == (d.dof_before, d.dof_after)


def test_candidate_likelihood_ratios_equal_the_dense_path(iso):
    s, d = iso
    compared = 0
    for name, c in d.candidates.items():
        if name.startswith("periodic_"):        # the period scan is dense-only (docs/diagnose.md)
            assert s.candidates[name].status == "not identifiable"
            continue
        assert s.candidates[name].status == c.status, name
        if c.delta_chi2 is not None:
            assert rel(s.candidates[name].delta_chi2, c.delta_chi2) <= REL, name
            compared += 1
    assert compared >= 5


def test_estimates_and_uncertainties_equal_the_dense_path(iso):
    s, d = iso
    assert rel(s.beta, d.beta) <= REL
    assert rel(np.sqrt(np.diag(s.cov_beta)), np.sqrt(np.diag(d.cov_beta))) <= REL
    assert rel(s.u_obs, d.u_obs) <= REL
    assert dg.effect_estimates(s, "scale")["estimate"] == pytest.approx(
        dg.effect_estimates(d, "scale")["estimate"], rel=REL)


def test_groups_equal_the_dense_path(iso):
    s, d = iso
    key = lambda g: (g["by"], g["group"])          # noqa: E731
    gd = {key(g): g for g in d.groups}
    assert {key(g) for g in s.groups} == set(gd) and len(gd) > 5
    for g in s.groups:
        assert rel(g["chi2"], gd[key(g)]["chi2"]) <= REL and g["dof"] == gd[key(g)]["dof"]


def test_large_length_records_choose_the_structured_path_by_themselves(monkeypatch):
    rec = sm.simulate(sm.iso10360(PAIR, repeats=2), MPE1, {}, seed=1)
    assert isinstance(dg.prepare(rec, MODEL).C, np.ndarray)
    monkeypatch.setattr(locator_model, "STRUCTURED_MIN_OBS", 50)
    assert isinstance(dg.prepare(rec, MODEL).C, sl.LengthCovariance)
    assert isinstance(dg.prepare(rec, MODEL, False).C, np.ndarray)


def test_records_without_a_probing_of_their_own_are_refused_with_the_reason(monkeypatch):
    """A chain of lengths x0-x1, x1-x2, ...: every inner probing is shared, a record's two ends
    both; forced structured is refused with the reason, automatic falls back to dense."""
    L = sm.stepgauge(PAIR, positions=("x",), steps=6)
    m = len(L.X)
    L.I, L.J = np.arange(m - 1), np.arange(1, m)
    L.ids, L.group = [f"c{a}" for a in range(m - 1)], ["x"] * (m - 1)
    L.time_s = L.time_s[:1].repeat(m - 1)
    rec = sm.simulate(L, MPE1, {}, seed=2)
    with pytest.raises(ModelError, match=r"have both probings shared.*\(diagnose --exact, calibrate --covariance dense\)"):
        dg.prepare(rec, MODEL, True)
    monkeypatch.setattr(locator_model, "STRUCTURED_MIN_OBS", 0)
    assert isinstance(dg.prepare(rec, MODEL).C, np.ndarray)


def test_group_statistics_that_would_not_fit_are_refused_beforehand(monkeypatch):
    from cmmwb.xlfuncs.memory import ResourceError

    rec = sm.simulate(sm.iso10360(PAIR, repeats=2), MPE1, {}, seed=1)
    monkeypatch.setattr(sl, "available_bytes", lambda: 50 * 2**20)
    with pytest.raises(ResourceError, match=r"group statistics of 70 length records need about .* GiB are available"):
        dg.diagnose(rec, MODEL, structured=True)
