"""REML on the structured record covariance of diagnose (xlfuncs/reml_structured.py, C = D + U U^T
never formed): the log-likelihood, its closed-form gradient, the expected information, the fitted
hyper-parameters with their u and the GLS checks equal the dense path's to relative 1e-8 on ISO
10360-2 lengths with three probes, a step gauge and point records; calibrate takes it above the
dense cap (and with --covariance structured)."""

import json
import math
from functools import cache

import numpy as np
import pytest

from cmmwb.xlfuncs import calibrate as cb
from cmmwb.xlfuncs import calibration_checks as checks
from cmmwb.xlfuncs import reml
from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.reml_structured import StructuredRecordCovariance

from tests.helpers import run_cmmwb
from tests.helpers.clouds import MPE1, PAIR, THREE
from tests.helpers.tasks import machine_task_toml

REL = 1e-8


def rel(a, b) -> float:
    a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


@cache
def prep(layout: str, probes: tuple, seed: int, **kw):
    rec = sm.simulate(sm.layout(layout, probes, **kw), MPE1, {}, seed=seed)
    return dg.prepare(rec, dg.Model(MPE1, probes, True), False)


def sets(structured: bool, size: str = "large") -> list[reml.RecordSet]:
    """ISO 10360-2 lengths (three probes with offsets) and a step gauge (two probes): 315 + 306
    records (large), 105 + 51 (small: five hyper-parameters estimated), 35 + 51 (tiny)."""
    iso = prep("iso10360", THREE, 3, repeats={"large": 9, "small": 3, "tiny": 1}[size])
    sg = prep("stepgauge", PAIR, 4, repeats=2) if size == "large" else prep("stepgauge", PAIR, 4, positions=("x",))
    return [reml.record_set(iso, "iso", structured=structured), reml.record_set(sg, "stepgauge", structured=structured)]


def values() -> dict[str, float]:
    return {n: float(getattr(MPE1, n)) for n in reml.NAMES}


def test_the_structured_likelihood_gradient_and_information_of_lengths_equal_the_dense_ones():
    dense, structured = sets(False), sets(True)
    assert sum(len(s.y) for s in dense) == 621
    assert all(isinstance(s.op, StructuredRecordCovariance) for s in structured)
    free = list(reml.NAMES)
    d = reml.reml_terms(dense, values(), free)
    s = reml.reml_terms(structured, values(), free)
    assert rel(s.loglik, d.loglik) <= REL and rel(s.chi2, d.chi2) <= REL
    # every gradient component to 1e-8 of itself (sigma_PQ has none with one probe per repeat: both 0)
    nz = np.abs(d.grad) > 0
    assert rel(s.grad[nz], d.grad[nz]) <= REL and np.all(s.grad[~nz] == 0)
    # the expected information to 1e-8 of sqrt(F_aa F_bb)
    scale = np.sqrt(np.outer(np.diag(d.fisher), np.diag(d.fisher)))
    assert np.max(np.abs(s.fisher - d.fisher) / np.maximum(scale, 1e-300)) <= REL


@pytest.mark.parametrize("layout,kw", [("spheres", {}), ("ballplate", {"grid": 3})])
def test_the_structured_likelihood_of_point_records_equals_the_dense_one(layout, kw):
    p = prep(layout, PAIR, 1, **kw)
    free = [n for n in reml.NAMES]
    d = reml.reml_terms([reml.record_set(p, structured=False)], values(), free)
    s = reml.reml_terms([reml.record_set(p, structured=True)], values(), free)
    assert rel(s.loglik, d.loglik) <= REL
    nz = np.abs(d.grad) > 0
    assert rel(s.grad[nz], d.grad[nz]) <= REL and np.all(np.abs(s.grad[~nz]) <= 1e-12)
    scale = np.sqrt(np.outer(np.diag(d.fisher), np.diag(d.fisher)))
    assert np.max(np.abs(s.fisher - d.fisher) / np.maximum(scale, 1e-300)) <= REL


def test_the_structured_gradient_is_the_derivative_of_the_structured_likelihood():
    s = sets(True, "tiny")
    v = values()
    free = list(reml.NAMES)
    t = reml.reml_terms(s, v, free, fisher=False)
    h = 1e-5
    for k, name in enumerate(free):
        up, dn = dict(v), dict(v)
        up[name] *= math.exp(h)
        dn[name] *= math.exp(-h)
        fd = (reml.reml_terms(s, up, []).loglik - reml.reml_terms(s, dn, []).loglik) / (2 * h)
        assert abs(t.grad[k] - fd) <= 1e-5 * max(1.0, abs(fd)), (name, t.grad[k], fd)


def test_the_fitted_hyper_parameters_and_their_u_equal_the_dense_fit():
    # the length scales held: their derivatives are checked above; fitting them too takes about
    # two minutes on the structured form at this n, whose columns outnumber the 156 records
    held = ("lambda_ET_mm", "lambda_ER_mm")
    d = cb.calibrate(sets(False, "small"), MPE1, fixed=held)
    s = cb.calibrate(sets(True, "small"), MPE1, fixed=held)
    assert s.free == d.free == ["sigma_R_um", "sigma_ET_um", "sigma_ER_urad"]
    for name, e in d.estimates.items():
        f = s.estimates[name]
        assert f.status == e.status, name
        assert rel(f.value, e.value) <= REL, name
        if e.u is not None:
            assert rel(f.u, e.u) <= REL, (name, f.u, e.u)
    assert rel(s.loglik, d.loglik) <= REL


def test_the_gls_checks_equal_the_dense_ones():
    p = prep("iso10360", THREE, 3, repeats=3)
    scale = p.design.ref[:, None] * 1.0          # a scale effect: the reference length (mm)
    d = reml.record_set(p, "iso", effect_X=scale, effect_labels=["scale"], structured=False)
    s = reml.record_set(p, "iso", effect_X=scale, effect_labels=["scale"], structured=True)
    bd, cd, xd, nd = checks.gls_fit(d, MPE1)
    bs, cs, xs, ns = checks.gls_fit(s, MPE1)
    assert nd == ns and rel(bs, bd) <= REL and rel(np.diag(cs), np.diag(cd)) <= REL and rel(xs, xd) <= REL
    for a, b in zip(checks.standardized_residuals(s, MPE1), checks.standardized_residuals(d, MPE1)):
        assert np.max(np.abs(a - b)) <= REL * np.max(np.abs(b))


def test_calibrate_takes_the_structured_covariance_above_the_dense_cap(monkeypatch):
    monkeypatch.setattr(reml, "DENSE_MAX_OBS", 400)      # the cap (4,000) lowered: 420 records
    rec = sm.simulate(sm.layout("iso10360", THREE, repeats=12), MPE1, {}, seed=2)
    assert rec.n == 420 > reml.DENSE_MAX_OBS
    assert reml.use_structured(rec) and not reml.use_structured(rec, "dense")
    p = dg.prepare(rec, dg.Model(MPE1, THREE, True), reml.use_structured(rec))
    s = reml.record_set(p, "iso")
    assert isinstance(s.op, StructuredRecordCovariance)
    with pytest.raises(ModelError, match="at most 400 observations per file: use --covariance structured"):
        reml.record_set(p, "iso", structured=False)


TASK = machine_task_toml(MPE1, [("P1", (0.0, 20.0, -30.0)), ("P2", (0.0, -20.0, -30.0))])


def test_the_covariance_option_gives_the_same_calibration(tmp_path):
    (tmp_path / "task.toml").write_text(TASK)
    env = {"OPENBLAS_NUM_THREADS": "1"}
    p = run_cmmwb("simulate", "--layout", "iso10360", "--task", "task.toml", "--seed", "5", "--out", "iso.csv",
                  cwd=tmp_path, env=env)
    assert p.returncode == 0, p.stderr
    out = {}
    for cov in ("dense", "structured"):
        p = run_cmmwb("calibrate", "iso.csv", "--task", "task.toml", "--covariance", cov, "--effects", "none",
                      "--no-workbook", "--out", cov, cwd=tmp_path, env=env)
        assert p.returncode == 0, p.stderr
        out[cov] = json.loads((tmp_path / cov / "calibration.json").read_text())
    d, s = out["dense"], out["structured"]
    # the profiles (9 refits per estimate) are left out on the structured covariance unless asked
    estimated = [h["name"] for h in d["hyper_parameters"] if h["status"] == "estimated"]
    assert d["profiles_note"] is None and [p["name"] for p in d["profiles"]] == estimated != []
    assert s["profiles"] == [] and "structured covariance" in s["profiles_note"]
    for hd, hs in zip(d["hyper_parameters"], s["hyper_parameters"]):
        assert hd["status"] == hs["status"] and rel(hs["estimate"], hd["estimate"]) <= REL, hd["name"]
        if hd["u"] is not None:
            assert rel(hs["u"], hd["u"]) <= REL, hd["name"]
    assert rel(s["chi2"]["after"], d["chi2"]["after"]) <= REL
    assert rel(s["residuals"][0]["z"], d["residuals"][0]["z"]) <= 1e-6
