"""The locator's small test layouts (ISO 10360 lengths with the MPE1 machine) and the diagnosis
workbook's expected rows."""

from __future__ import annotations

import math

from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import effects as fx
from cmmwb.xlfuncs.locator import simulate as sm

from tests.helpers.clouds import MPE1, ONE


def iso(repeats: int = 3):
    return sm.layout("iso10360", ONE, repeats=repeats), dg.Model(MPE1, ONE, True)


def u_effect(L, model, name: str) -> float:
    prep = dg.prepare(sm.simulate(L, MPE1, {}, seed=0), model)
    cov, _ = dg.effect_covariance(prep, name)
    return math.sqrt(cov[0, 0])


def expected_rows(result):
    exp = {k: result[k] for k in ("chi2_before", "dof_before", "p_before", "chi2_after", "dof_after",
                                  "rms_before_um", "rms_after_um", "p_after")}
    exp["p_targeted"] = result["p_targeted"] if result["p_targeted"] is not None else 1.0
    unc = {}
    if result["noise_scale"]:
        exp["noise_scale"], unc["noise_scale"] = result["noise_scale"]["estimate"], result["noise_scale"]["u"]
    for o in result["outliers"] or []:
        if isinstance(o["estimate_um"], list):        # a point: one mean shift per coordinate
            for a, v, u in zip(o["axes"], o["estimate_um"], o["u_um"]):
                exp[f"outlier {o['id']}.{a}"], unc[f"outlier {o['id']}.{a}"] = v, u
        else:
            exp[f"outlier {o['id']}"], unc[f"outlier {o['id']}"] = o["estimate_um"], o["u_um"]
    for e in result["effects"]:
        if isinstance(e["estimate"], list):
            labels = ([f"{pp['probe']}.d{a}" for pp in e["per_probe"] for a in "xyz"]
                      if e["name"] == "probe_qualification" else ["c2", "c3"] if e["name"] in fx.STRAIGHTNESS
                      else [f"{p}.{h}" for p in ("P1", "P2") for h in ("c2", "s2", "c3", "s3", "c4", "s4")]
                      if e["name"] == "probe_lobing" else ["a", "b"] if e["name"] in fx.PERIODIC
                      else [f"v{a}" for a in "xyz"])
            for lab, v, u in zip(labels, e["estimate"], e["u"]):
                if v is not None:
                    exp[f"{e['name']} {lab}"], unc[f"{e['name']} {lab}"] = v, u
            if e["name"] in fx.PERIODIC:
                exp[f"{e['name']} period_mm"], unc[f"{e['name']} period_mm"] = e["period_mm"], e["u_period_mm"]
        else:
            exp[e["name"]], unc[e["name"]] = e["estimate"], e["u"]
    return exp, unc
