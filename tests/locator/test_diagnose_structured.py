"""The mismatch locator on point records with the structured covariance C = D + U U^T
(xlfuncs.locator.structured: never n x n, GP factors by controlled low-rank factors) gives the dense
path's chi-square, p-values, choices, estimates and uncertainties to relative 1e-8."""

import json

import numpy as np
import pytest

from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import model as locator_model
from cmmwb.xlfuncs.locator import simulate as sm

from tests.helpers import ENGINES
from tests.helpers import max_rel_diff as rel
from tests.helpers.clouds import MPE1, PAIR

REL = 1e-8


@pytest.fixture(scope="module")
def both():
    """A dense scan of four spheres (400 points, two probes) with planted scale (5 ppm) and
    probe-radius (2 µm) errors, diagnosed both ways."""
    rec = sm.simulate(sm.scan(PAIR, points=400), MPE1, {"scale": 5.0, "probe_radius": 2.0}, seed=3)
    model = dg.Model(MPE1, PAIR, True)
    return dg.diagnose(rec, model, structured=True), dg.diagnose(rec, model, structured=False)


def test_the_structured_covariance_is_not_a_matrix(both):
    s, d = both
    assert not isinstance(s.prep.C, np.ndarray) and isinstance(d.prep.C, np.ndarray)
    assert s.whitener.mode == "structured"


def test_both_planted_effects_are_found_by_both_paths(both):
    s, d = both
    assert s.chosen == d.chosen and set(s.chosen) == {"scale", "probe_radius"}


def test_chi_square_and_p_values_equal_the_dense_path(both):
    s, d = both
    assert rel(s.chi2_before, d.chi2_before) <= REL
    assert rel(s.chi2_after, d.chi2_after) <= REL
    assert rel(s.logp_before, d.logp_before) <= REL
    assert (s.dof_before, s.dof_after) == (d.dof_before, d.dof_after)


def test_candidate_likelihood_ratios_equal_the_dense_path(both):
    s, d = both
    for name, c in d.candidates.items():
        assert s.candidates[name].status == c.status, name
        if c.delta_chi2 is not None:
            assert rel(s.candidates[name].delta_chi2, c.delta_chi2) <= REL, name
            assert rel(s.candidates[name].logp, c.logp) <= REL, name


def test_estimates_and_uncertainties_equal_the_dense_path(both):
    s, d = both
    assert rel(s.beta, d.beta) <= REL
    assert rel(np.sqrt(np.diag(s.cov_beta)), np.sqrt(np.diag(d.cov_beta))) <= REL
    assert rel(s.u_obs, d.u_obs) <= REL
    assert rel(s.z_after, d.z_after) <= 1e-6 or np.max(np.abs(s.z_after - d.z_after)) <= 1e-8


def test_groups_and_located_records_equal_the_dense_path(both):
    s, d = both
    key = lambda g: (g["by"], g["group"])          # noqa: E731
    gd = {key(g): g for g in d.groups}
    assert {key(g) for g in s.groups} == set(gd)
    for g in s.groups:
        assert rel(g["chi2"], gd[key(g)]["chi2"]) <= REL and g["dof"] == gd[key(g)]["dof"]
    assert [r["id"] for r in s.located] == [r["id"] for r in d.located]
    assert rel([r["z"] for r in s.located], [r["z"] for r in d.located]) <= REL


def test_the_json_states_the_approximation(both):
    s, d = both
    out = json.loads(json.dumps(dg.diagnosis_json(s), default=str))
    a = out["approximation"]
    assert set(a["rank"]) == {"ET", "ER", "P0", "P1"}
    assert 0 < a["chi2_relative_error_bound"] <= 1e-8
    assert "approximation" not in dg.diagnosis_json(d)


def test_large_point_records_choose_the_structured_path_by_themselves():
    L = sm.scan(PAIR, points=2100)            # 6300 observations > STRUCTURED_MIN_OBS
    rec = sm.simulate(L, MPE1, {}, seed=1)
    prep = dg.prepare(rec, dg.Model(MPE1, PAIR, True))
    assert not isinstance(prep.C, np.ndarray)
    small = dg.prepare(sm.simulate(sm.scan(PAIR, points=300), MPE1, {}, seed=1), dg.Model(MPE1, PAIR, True))
    assert isinstance(small.C, np.ndarray)


@pytest.mark.parametrize("engine", ENGINES)
def test_the_workbook_of_a_structured_diagnosis_agrees_with_its_json(tmp_path, monkeypatch, engine):
    """The whitened GLS sheet holds the structured whitener's coordinates (fewer than n) and the
    rank of C as a number; every engine reproduces chi-square, dof and estimates of the JSON."""
    from cmmwb.generator.diagnosis import book as diagnose_book
    from cmmwb.generator.diagnosis.run import run_diagnose
    from cmmwb.generator.workbook.recalc import results_rows
    from cmmwb.xlfuncs.locator.recordings import write_recordings

    from tests.helpers import close, recalc
    from tests.helpers.locator import expected_rows

    monkeypatch.setattr(locator_model, "STRUCTURED_MIN_OBS", 0)
    monkeypatch.setattr(diagnose_book, "NATIVE_MAX_OBS", 20)
    rec = sm.simulate(sm.scan(PAIR, points=200), MPE1, {"scale": 10.0, "probe_radius": 3.0}, seed=3)
    write_recordings(rec, tmp_path / "rec.csv")
    result, _ = run_diagnose(tmp_path / "rec.csv", dg.Model(MPE1, PAIR, True), tmp_path / "out", plots=False)
    assert "approximation" in result and result["dof_before"] == 3 * 200 - 6
    rows = {r["quantity"]: r for r in results_rows(recalc(tmp_path / "out" / "diagnosis.xlsx", engine))}
    exp, unc = expected_rows(result)
    for q, v in exp.items():
        assert close(rows[q]["value"], v), f"{engine}: {q} {rows[q]['value']!r} != {v!r}"
        if q in unc:
            assert close(rows[q]["u"], unc[q]), f"{engine}: u({q})"
