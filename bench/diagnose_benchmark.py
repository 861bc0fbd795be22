"""Rate benchmark of the mismatch locator (``cmmwb diagnose``): does it find concealed effects,
estimate them right, and stay quiet on records that agree with the simulation?

Every data set is simulated by :mod:`xlfuncs.locator.simulate` (a CMM drawn from the Forbes 2025 model
with the Table 3 MPE1 parameters, plus planted effects) and diagnosed with the same MPE1 model.
Nothing is tuned per effect: the selection threshold is alpha = 0.01 with the Bonferroni factor
of docs/recordings.md section 3.3, and every planted effect gets its size from one rule:

    size = SNR x (its GLS standard uncertainty in that design),  SNR ~ U[SNR_LO, SNR_HI],
    random sign (vector effects: random direction in the parameter space, Mahalanobis length SNR)

i.e. the same aggregate signal-to-noise ratio for every effect and design.  How concealed that is
in each record is measured and reported (the largest single-record shift in units of that
record's standard uncertainty).

Second edition (docs/recordings.md section 7): sets with one gross outlier (G ~ U[6, 12] standard
uncertainties), sets with inflated noise (every random factor, or the repeatability alone, x U[1.3, 2]), and a power curve of the
two gates against the omnibus gate alone and the oracle.

Concealment categories (issue 5):

* ``small``    spread over all records, too small to see in any single record
* ``subset``   visible only in a subset: diagonal lengths, one probe, warm records, late records,
               bidirectional lengths
* ``masked``   two planted effects, the concealed one hidden behind a larger one (SNR x 3)
* ``aliased-unless``  aliased with another candidate unless the records' probe offsets, normals,
               temperatures or times are used
* ``aliased``  truly aliased designs (one probe offset): the effect must be *reported* aliased,
               naming the look-alike and the measurement that separates them

Usage::

    python bench/diagnose_benchmark.py                 # full benchmark (~3-5 min on one core)
    python bench/diagnose_benchmark.py --quick 20      # 20 effect sets + 20 null sets

Writes ``bench/results/diagnose_rates.md`` (the table docs/benchmarks.md quotes) and, with ``--json``,
``bench/results/diagnose_benchmark.json`` (every data set, about 0.5 MB).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cmmwb.xlfuncs import pointcloud as pc  # noqa: E402
from cmmwb.xlfuncs.locator import diagnose as dg  # noqa: E402
from cmmwb.xlfuncs.locator import effects as fx  # noqa: E402
from cmmwb.xlfuncs.locator import simulate as sm  # noqa: E402
from cmmwb.xlfuncs.model import MPE1  # noqa: E402  (Forbes 2025 Table 3)

SNR_LO, SNR_HI = 10.0, 13.0
MASK_FACTOR = 3.0
ALPHA = 0.01

ONE = (pc.Probe("P1", (0.0, 0.0, -50.0)),)
THREE = (pc.Probe("P1", (0.0, 0.0, -50.0)), pc.Probe("P2", (150.0, 0.0, -50.0)), pc.Probe("P3", (0.0, 150.0, -50.0)))
PAIR = (pc.Probe("P1", (0.0, 20.0, -30.0)), pc.Probe("P2", (0.0, -20.0, -30.0)))


@dataclass
class Scenario:
    label: str
    category: str
    layout: str
    probes: tuple
    effects: tuple[str, ...] = ()        # planted (first = concealed one for masked sets)
    temperature: object = 20.0           # None, T, (T0, T1) ramp, ("warm", T_lo, T_hi): last third warm,
    #                                      ("bump", T0, T1): up to T1 and back over the session
    layout_kw: dict = field(default_factory=dict)
    expect_alias: tuple[str, str] | None = None   # (planted, chosen look-alike)


def scenarios(second_edition: bool = True) -> list[Scenario]:
    """Every effect scenario; ``second_edition=False``: the first edition's only (the quick run,
    whose new-candidate counterparts are tests/locator/test_diagnose_new_candidates.py)."""
    S = []
    iso1 = dict(layout="iso10360", probes=ONE)
    iso3 = dict(layout="iso10360", probes=THREE)
    # -- small: below about 2-3 standard uncertainties in every single record --------------
    iso5 = dict(layout="iso10360", probes=ONE, layout_kw={"repeats": 5})
    S += [Scenario("thermal_expansion, ISO 10360-2 x5, temperature up and down", "small",
                   effects=("thermal_expansion",), temperature=("bump", 20.0, 22.0), **iso5),
          Scenario("scale_drift, ISO 10360-2 x5", "small", effects=("scale_drift",), **iso5),
          Scenario("offset_drift, hole plate (2-D, two passes)", "small", "holeplate", PAIR[:1], ("offset_drift",),
                   layout_kw={"passes": 2}),
          Scenario("offset_drift, ball plate (four passes)", "small", "ballplate", PAIR[:1], ("offset_drift",),
                   layout_kw={"passes": 4}),
          Scenario("probe_radius, hole plate (2-D)", "small", "holeplate", PAIR[:1], ("probe_radius",)),
          Scenario("probe_radius, spheres", "small", "spheres", ONE, ("probe_radius",))]
    # -- subset: only part of the records respond ------------------------------------------
    for e in ("scale_x", "scale_y", "scale_z"):
        S.append(Scenario(f"{e}, ISO 10360-2 (lengths along that axis)", "subset", effects=(e,), **iso1))
    for e in ("squareness_xy", "squareness_xz", "squareness_yz"):
        S.append(Scenario(f"{e}, ISO 10360-2 (diagonal lengths)", "subset", effects=(e,), **iso1))
    S += [Scenario("thermal_expansion, ISO 10360-2 (warm last round)", "subset", effects=("thermal_expansion",),
                   temperature=("warm", 22.0, 24.0), **iso1),
          Scenario("probe_radius, step gauge (LR lengths)", "subset", "stepgauge", ONE, ("probe_radius",)),
          Scenario("probe_qualification, step gauge (two probes)", "subset", "stepgauge", PAIR,
                   ("probe_qualification",)),
          Scenario("probe_qualification, ball plate (second pass)", "subset", "ballplate", PAIR,
                   ("probe_qualification",)),
          Scenario("probe_qualification, spheres", "subset", "spheres", PAIR, ("probe_qualification",)),
          Scenario("scale_drift, ISO 10360-2 (late records)", "subset", effects=("scale_drift",), **iso1),
          Scenario("offset_drift, ball plate (second pass)", "subset", "ballplate", PAIR[:1], ("offset_drift",))]
    # -- aliased unless the probe offsets / normals / temperatures / times are used ---------
    for e in fx.ANGULAR:
        S.append(Scenario(f"{e}, ISO 10360-2 with three probe offsets", "aliased-unless", effects=(e,), **iso3))
    S += [Scenario("ECX, step gauge with two probe offsets (±20 mm in y)", "aliased-unless", "stepgauge", PAIR, ("ECX",)),
          Scenario("EAZ, spheres with two probe offsets", "aliased-unless", "spheres", PAIR, ("EAZ",)),
          Scenario("thermal_expansion, ISO 10360-2, 19.5-22.5 °C ramp", "aliased-unless",
                   effects=("thermal_expansion",), temperature=(19.5, 22.5), **iso1),
          Scenario("scale with a temperature ramp (vs thermal)", "aliased-unless", effects=("scale",),
                   temperature=(19.5, 22.5), **iso1),
          Scenario("scale_drift, temperature rising and falling (vs thermal, scale)", "aliased-unless",
                   effects=("scale_drift",), temperature=("bump", 20.0, 23.0), **iso1),
          Scenario("thermal_expansion, temperature rising and falling (vs scale_drift)", "aliased-unless",
                   effects=("thermal_expansion",), temperature=("bump", 20.0, 23.0), **iso1),
          Scenario("offset_drift, ball plate, two probes (vs probe_qualification)", "aliased-unless", "ballplate",
                   PAIR, ("offset_drift",)),
          Scenario("probe_radius vs probe_qualification, step gauge", "aliased-unless", "stepgauge", PAIR,
                   ("probe_radius",))]
    # -- masked: a larger effect hides the concealed one -----------------------------------
    S += [Scenario("squareness_xy behind scale", "masked", effects=("squareness_xy", "scale"), **iso1),
          Scenario("scale_drift behind thermal_expansion", "masked", effects=("scale_drift", "thermal_expansion"),
                   temperature=("bump", 20.0, 23.0), **iso1),
          Scenario("EBX behind scale_x (three probe offsets)", "masked", effects=("EBX", "scale_x"), **iso3),
          Scenario("probe_radius behind probe_qualification", "masked", "stepgauge", PAIR,
                   ("probe_radius", "probe_qualification")),
          Scenario("thermal_expansion behind squareness_xz", "masked", effects=("thermal_expansion", "squareness_xz"),
                   temperature=("warm", 22.0, 24.0), **iso1),
          Scenario("offset_drift behind scale", "masked", "ballplate", PAIR[:1], ("offset_drift", "scale")),
          Scenario("ECZ behind squareness_yz (three probe offsets)", "masked", effects=("ECZ", "squareness_yz"), **iso3),
          Scenario("probe_qualification behind probe_radius, spheres", "masked", "spheres", PAIR,
                   ("probe_qualification", "probe_radius")),
          Scenario("scale behind squareness_xy", "masked", effects=("scale", "squareness_xy"), **iso1),
          Scenario("scale_y behind scale", "masked", effects=("scale_y", "scale"), **iso1),
          Scenario("probe_qualification behind offset_drift, ball plate", "masked", "ballplate", PAIR,
                   ("probe_qualification", "offset_drift"))]
    if not second_edition:
        return S
    # -- second edition (docs/recordings.md section 7): straightness and reversal, concealed the
    # same four ways -----------------------------------------------------------------------------
    plate4 = dict(layout="ballplate", probes=PAIR[:1], layout_kw={"passes": 4})
    holes2 = dict(layout="holeplate", probes=PAIR[:1], layout_kw={"passes": 2})
    iso2 = dict(layout="iso10360", probes=PAIR)
    S += [Scenario("EYX, ball plate (four passes)", "small", effects=("EYX",), **plate4),
          Scenario("EXY, ball plate (four passes)", "small", effects=("EXY",), **plate4),
          Scenario("reversal_y, hole plate (2-D, two passes)", "small", effects=("reversal_y",), **holes2),
          Scenario("reversal_x, spheres", "small", "spheres", PAIR, ("reversal_x",))]
    S += [Scenario(f"{e}, ISO 10360-2 (diagonal lengths)", "subset", effects=(e,), **iso1)
          for e in ("EZX", "EXZ", "EZY", "EYZ")]
    S += [Scenario(f"{e}, ISO 10360-2, two probes (lengths probed from both sides)", "subset", effects=(e,), **iso2)
          for e in ("reversal_x", "reversal_z")]
    S += [Scenario("reversal_x vs probe_radius, hole plate (normals along y tell them apart)", "aliased-unless",
                   effects=("reversal_x",), **holes2),
          Scenario("EYX vs squareness_xy, ball plate, two probes", "aliased-unless", "ballplate", PAIR, ("EYX",))]
    # thermal gradient: temperatures varying, records spread along the axis
    S += [Scenario("thermal_gradient_y, ball plate (four passes), temperature up and down", "small",
                   effects=("thermal_gradient_y",), temperature=("bump", 20.0, 23.0), **plate4),
          Scenario("thermal_gradient_x, spheres, temperature up and down", "small", "spheres", PAIR,
                   ("thermal_gradient_x",), temperature=("bump", 20.0, 23.0)),
          Scenario("thermal_gradient_x, ball plate (four passes, warm last third)", "subset",
                   effects=("thermal_gradient_x",), temperature=("warm", 22.0, 24.0), **plate4),
          Scenario("thermal_gradient_y, step gauge, temperature up and down", "subset", "stepgauge", ONE,
                   ("thermal_gradient_y",), temperature=("bump", 20.0, 23.0)),
          Scenario("thermal_gradient_z, spheres, 19.5-22.5 °C ramp (vs thermal_expansion)", "aliased-unless",
                   "spheres", PAIR, ("thermal_gradient_z",), temperature=(19.5, 22.5)),
          Scenario("thermal_gradient_x behind thermal_expansion, ball plate", "masked",
                   effects=("thermal_gradient_x", "thermal_expansion"), temperature=("bump", 20.0, 23.0), **plate4)]
    # probe lobing: points approached from many directions around the stylus axis
    S += [Scenario("probe_lobing, spheres, two probes", "small", "spheres", PAIR, ("probe_lobing",)),
          Scenario("probe_lobing vs probe_radius, spheres, one probe", "aliased-unless", "spheres", ONE,
                   ("probe_lobing",)),
          Scenario("probe_lobing behind probe_radius, spheres", "masked", "spheres", PAIR,
                   ("probe_lobing", "probe_radius"))]
    # periodic errors: records that sample the axis densely, a step gauge or a hole plate (a ball
    # plate's or ISO 10360-2's few positions cannot tell a sine from a bump: not identifiable there)
    sg1 = dict(layout="stepgauge", probes=ONE)
    S += [Scenario("periodic_x, step gauge (along x, y and the xy diagonal)", "small", effects=("periodic_x",), **sg1),
          Scenario("periodic_y, hole plate (2-D, two passes)", "small", effects=("periodic_y",), **holes2),
          Scenario("periodic_y, step gauge, two probes (lengths along y and xy respond)", "subset", "stepgauge", PAIR,
                   ("periodic_y",)),
          Scenario("periodic_x behind scale_x, step gauge", "masked", effects=("periodic_x", "scale_x"), **sg1),
          Scenario("periodic_x behind probe_radius, hole plate", "masked", effects=("periodic_x", "probe_radius"),
                   **holes2)]
    S += [Scenario("EYX behind squareness_xy, ball plate", "masked", "ballplate", PAIR, ("EYX", "squareness_xy")),
          Scenario("reversal_y behind probe_radius, hole plate", "masked", effects=("reversal_y", "probe_radius"),
                   **holes2)]
    return S


ALIASED = [Scenario("EBX, one probe offset (looks like scale_x)", "aliased", effects=("EBX",), layout="iso10360",
                    probes=ONE, expect_alias=("EBX", "scale_x")),
           Scenario("EAX, one probe offset (looks like squareness_xy)", "aliased", effects=("EAX",),
                    layout="iso10360", probes=ONE, expect_alias=("EAX", "squareness_xy"))]

def _varied(category: str, first_label: str, first_kw: dict) -> list[Scenario]:
    """The six layouts of the null and outlier sets (``first_*``: the plain ISO 10360-2 one)."""
    return [Scenario(f"{category}, {first_label}", category, "iso10360", ONE, layout_kw=first_kw),
            Scenario(f"{category}, ISO 10360-2, three probes, ramp", category, "iso10360", THREE,
                     temperature=(19.5, 22.5)),
            Scenario(f"{category}, step gauge, two probes", category, "stepgauge", PAIR),
            Scenario(f"{category}, ball plate", category, "ballplate", PAIR),
            Scenario(f"{category}, hole plate (2-D)", category, "holeplate", PAIR[:1], layout_kw={"passes": 2}),
            Scenario(f"{category}, spheres", category, "spheres", PAIR)]


NULLS = _varied("null", "ISO 10360-2", {})


#: second edition (docs/recordings.md section 7): one gross single-record error, size
#: G x (that record's standard uncertainty under the simulation), G ~ U[GROSS_LO, GROSS_HI]
GROSS_LO, GROSS_HI = 6.0, 12.0
OUTLIERS = _varied("outlier", "ISO 10360-2 x3", {"repeats": 3})
#: inflated noise: every random factor of the simulated machine f times the declared one,
#: f ~ U[NOISE_LO, NOISE_HI]; diagnosed with the declared MPE1 model
NOISE_LO, NOISE_HI = 1.3, 2.0
NOISE = [Scenario("noise, ISO 10360-2 x3", "noise", "iso10360", ONE, layout_kw={"repeats": 3}),
         Scenario("noise, ISO 10360-2 x5", "noise", "iso10360", ONE, layout_kw={"repeats": 5}),
         Scenario("noise, step gauge, two probes", "noise", "stepgauge", PAIR),
         Scenario("noise, ball plate (four passes)", "noise", "ballplate", PAIR[:1], layout_kw={"passes": 4}),
         Scenario("noise, spheres", "noise", "spheres", PAIR),
         Scenario("noise, hole plate (2-D, two passes)", "noise", "holeplate", PAIR[:1], layout_kw={"passes": 2})]
#: the same with only the repeatability sigma_R inflated (the covariance then grows non-uniformly)
NOISE += [replace(s, label=s.label.replace("noise,", "noise (repeatability only),")) for s in NOISE]
SIGMAS = ("sigma_R_um", "sigma_S_ppm", "sigma_Sa_ppm", "sigma_Q_ppm", "sigma_PQ_um", "sigma_ET_um",
          "sigma_ER_urad", "sigma_P0_um", "sigma_P_um")


def plant_outlier(rec, model, rng) -> tuple[str, float]:
    """One gross error in one random record (a point: along a random direction), G x its standard
    uncertainty (points: Mahalanobis length G with the point's covariance block)."""
    prep = dg.prepare(rec, model)
    G = rng.uniform(GROSS_LO, GROSS_HI)
    a = int(rng.integers(rec.n))
    if prep.design.kind == "length":
        rec.measured_mm[a] += rng.choice((-1.0, 1.0)) * G * math.sqrt(prep.C[a, a]) / 1000.0
    else:
        dims = prep.design.dims
        B = prep.C[dims * a:dims * a + dims, dims * a:dims * a + dims]
        d = rng.standard_normal(dims)
        d /= np.linalg.norm(d)
        t = G / math.sqrt(d @ np.linalg.solve(B, d))
        rec.X_mm[a, :dims] += t * d / 1000.0
    return rec.ids[a], G


def temperatures(spec, L: sm.Layout):
    if isinstance(spec, tuple) and spec and spec[0] == "bump":
        # warms up and cools down again over the session
        return spec[1] + (spec[2] - spec[1]) * np.sin(np.pi * L.time_s / L.time_s.max())
    if isinstance(spec, tuple) and spec and spec[0] == "warm":
        T = np.full(L.n, 20.0)
        late = L.time_s > np.quantile(L.time_s, 2 / 3)
        T[late] = np.linspace(spec[1], spec[2], int(late.sum()))
        return T
    return spec


def planted_values(name: str, beta: np.ndarray, labels: list[str]):
    if name == "probe_qualification":
        out: dict = {}
        for l, b in zip(labels, beta):
            pid, comp = l.split(".d")
            out.setdefault(pid, [0.0, 0.0, 0.0])["xyz".index(comp)] = float(b)
        return out
    if name == "offset_drift":
        v = [0.0, 0.0, 0.0]
        for l, b in zip(labels, beta):
            v["xyz".index(l[1])] = float(b)
        return v
    if name == "probe_lobing":           # {probe: (c2, s2, c3, s3, c4, s4)} (µm)
        out = {}
        for l, b in zip(labels, beta):
            pid, h = l.split(".")
            out.setdefault(pid, [0.0] * 6)[("c2", "s2", "c3", "s3", "c4", "s4").index(h)] = float(b)
        return out
    if name in fx.STRAIGHTNESS:          # c2, c3 (µm); an order the design does not see stays 0
        v = [0.0, 0.0]
        for l, b in zip(labels, beta):
            v[int(l[1]) - 2] = float(b)
        return v
    return float(beta[0])


def run_set(sc: Scenario, seed: int, debug: bool = False) -> dict:
    rng = np.random.default_rng(seed)
    L = sm.layout(sc.layout, sc.probes, **sc.layout_kw)
    T = temperatures(sc.temperature, L)
    model = dg.Model(MPE1, sc.probes, True)
    truth: dict[str, tuple[np.ndarray, list[str]]] = {}
    planted = {}
    periods: dict[str, float] = {}
    visibility = []
    if sc.effects:
        rec0 = sm.simulate(L, MPE1, {}, rng=np.random.default_rng(seed + 10**6), temperature_C=T)
        prep = dg.prepare(rec0, model)
        W = dg.Whitener(prep.C)
        u_marg = np.sqrt(np.diag(prep.C))
        for q, name in enumerate(sc.effects):
            period = None
            if name in fx.PERIODIC:         # a period drawn from those the records identify
                lo, hi, _ = fx.period_range(prep.design, fx.AXES.index(name[-1]))
                period = float(rng.uniform(lo, hi))
            cov, labels = dg.effect_covariance(prep, name, W, period_mm=period)
            snr = rng.uniform(SNR_LO, SNR_HI) * (MASK_FACTOR if (sc.category == "masked" and q == 1) else 1.0)
            # a random direction d in the parameter space (µm, µm/h), scaled to Mahalanobis length
            # SNR: components the design hardly sees (a probe offset along z on a flat artefact,
            # u of millimetres) stay the size of the others instead of taking the whole length
            z = rng.standard_normal(len(labels))
            d = z / np.linalg.norm(z)
            beta = snr * d / math.sqrt(float(d @ np.linalg.solve(cov, d)))
            truth[name] = (beta, labels, snr)
            planted[name] = planted_values(name, beta, labels)
            if period is not None:
                planted[name] = [float(beta[0]), float(beta[1]), period]
                periods[name] = period
            cols = fx.columns(prep.design, name, period)
            idx = [cols.labels.index(l) for l in labels]
            shift = cols.X[:, idx] @ beta
            visibility.append(float(np.max(np.abs(shift) / u_marg)))
    params = MPE1
    extra = {}
    if sc.category == "noise":
        f = rng.uniform(NOISE_LO, NOISE_HI)
        keys = ("sigma_R_um",) if "repeatability only" in sc.label else SIGMAS
        params = replace(MPE1, **{k: getattr(MPE1, k) * f for k in keys})
        extra["noise_factor"] = f
    rec = sm.simulate(L, params, planted, rng=rng, temperature_C=T)
    if sc.category == "outlier":
        extra["outlier"], extra["gross_sd"] = plant_outlier(rec, model, rng)
    t0 = time.perf_counter()
    diag = dg.diagnose(rec, model, ALPHA)
    elapsed = time.perf_counter() - t0
    j = diag.to_json()
    out = {"label": sc.label, "category": sc.category, "seed": seed, "layout": sc.layout,
           "records": rec.n, "mismatch": j["mismatch"], "chosen": [e["name"] for e in j["effects"]],
           "chi2_excess_sd": (j["chi2_before"] - j["dof_before"]) / math.sqrt(2 * j["dof_before"]),
           "planted": {k: {"snr": v[2], "values": [float(b) for b in v[0]], "labels": v[1]} for k, v in truth.items()},
           "max_record_z": visibility, "seconds": elapsed,
           # second edition (docs/recordings.md section 7)
           "gate": j["gate"], "omnibus_alone": bool(j["p_before"] < ALPHA), "p_targeted": j["p_targeted"],
           "explained": j["explained"], "outliers": [o["id"] for o in (j["outliers"] or [])],
           "indicated": [e["name"] for e in j["indicated"]],
           "noise_scale": j["noise_scale"], "dof": j["dof_before"],
           "df": {k: len(v[1]) for k, v in truth.items()}, **extra}
    within = {}
    for name, (beta, labels, _) in truth.items():
        e = next((x for x in j["effects"] if x["name"] == name), None)
        if e is None:
            continue
        if isinstance(e["estimate"], list):
            lab = diag.candidates[name].cols.labels
            ok = True
            for l, b in zip(labels, beta):
                k = lab.index(l)
                est, u = e["estimate"][k], e["u"][k]
                if est is None:
                    ok = False
                    continue
                ok &= abs(est - b) <= 3 * u
            if name in periods:             # and the period within 3 u of the planted one
                ok &= abs(e["period_mm"] - periods[name]) <= 3 * e["u_period_mm"]
            within[name] = bool(ok)
        else:
            within[name] = bool(abs(e["estimate"] - beta[0]) <= 3 * e["u"])
    out["within_3u"] = within
    if debug:
        out["json"] = j
    if sc.expect_alias:
        pl, look = sc.expect_alias
        item = next((x for x in j["not_identifiable"] if x["name"] == pl), None)
        out["alias_reported"] = bool(item is not None and item.get("aliased_with") == look
                                     and "second probe offset" in item["reason"])
        out["alias_reason"] = item["reason"] if item else None
    return out


#: the candidates of the locator's second edition (docs/recordings.md section 7)
NEW = set(fx.STRAIGHTNESS) | set(fx.REVERSAL) | set(fx.GRADIENT) | {"probe_lobing"} | set(fx.PERIODIC)


def rate(k: int, n: int) -> str:
    return f"{k}/{n} = {100.0 * k / n:.1f} %" if n else "—"


def _outlier_ok(r) -> bool:
    return r["outliers"][:1] == [r["outlier"]] and not r["chosen"]


def _noise_ok(r) -> bool:
    return r["noise_scale"] is not None and not r["chosen"]


def special_rows(results: list[dict]) -> list[str]:
    out = [r for r in results if r["category"] == "outlier"]
    noise = [r for r in results if r["category"] == "noise"]
    rows = []
    if out:
        rows += [f"| one gross outlier ({GROSS_LO:g}-{GROSS_HI:g} u): named first in `outliers`, no effect chosen | "
                 f"{rate(sum(_outlier_ok(r) for r in out), len(out))} | ≥ 95 % |"]
    if noise:
        rows += [f"| inflated noise ({NOISE_LO:g}-{NOISE_HI:g}x): `noise_scale` given, no effect chosen | "
                 f"{rate(sum(_noise_ok(r) for r in noise), len(noise))} | ≥ 95 % |"]
    return rows


def special_sections(results: list[dict]) -> list[str]:
    lines = []
    out = [r for r in results if r["category"] == "outlier"]
    if out:
        lines += ["", "## One gross outlier (docs/recordings.md section 7)", "",
                  f"One record (a point: along a random direction) shifted by G x its standard uncertainty, "
                  f"G ~ U[{GROSS_LO:g}, {GROSS_HI:g}]; no effect planted.", "",
                  "| layout | sets | mismatch | outlier named first | no effect chosen | both | explained |",
                  "|---|---|---|---|---|---|---|"]
        for label in dict.fromkeys(r["label"] for r in out):
            rs = [r for r in out if r["label"] == label]
            lines.append(f"| {label} | {len(rs)} | {rate(sum(r['mismatch'] for r in rs), len(rs))} | "
                         f"{rate(sum(r['outliers'][:1] == [r['outlier']] for r in rs), len(rs))} | "
                         f"{rate(sum(not r['chosen'] for r in rs), len(rs))} | "
                         f"{rate(sum(_outlier_ok(r) for r in rs), len(rs))} | "
                         f"{rate(sum(bool(r['explained']) for r in rs), len(rs))} |")
        bad = [r for r in out if not _outlier_ok(r)]
        if bad:
            lines += ["", "| misses: layout | seed | G | outlier | flagged | chosen |", "|---|---|---|---|---|---|"]
            for r in bad[:20]:
                lines.append(f"| {r['label']} | {r['seed']} | {r['gross_sd']:.1f} | {r['outlier']} | "
                             f"{', '.join(r['outliers']) or '—'} | {', '.join(r['chosen']) or '—'} |")
    noise = [r for r in results if r["category"] == "noise"]
    if noise:
        lines += ["", "## Inflated noise (docs/recordings.md section 7)", "",
                  f"Every random factor of the simulated machine f times the declared one, f ~ U[{NOISE_LO:g}, "
                  f"{NOISE_HI:g}]; diagnosed with the declared model.  \"repeatability only\": only sigma_R "
                  "inflated, so the covariance grows more for short lengths and points than for long lengths; "
                  "noise_scale is then the factor on the whole covariance, not f (no 3 u column).", "",
                  "| layout | dof | sets | mismatch | noise_scale given | no effect chosen | both | "
                  "within 3 u of f |", "|---|---|---|---|---|---|---|---|"]
        for label in dict.fromkeys(r["label"] for r in noise):
            rs = [r for r in noise if r["label"] == label]
            est = [abs(r["noise_scale"]["estimate"] - r["noise_factor"]) <= 3 * r["noise_scale"]["u"]
                   for r in rs if r["noise_scale"] and "repeatability only" not in label]
            lines.append(f"| {label} | {rs[0]['dof']} | {len(rs)} | {rate(sum(r['mismatch'] for r in rs), len(rs))} | "
                         f"{rate(sum(r['noise_scale'] is not None for r in rs), len(rs))} | "
                         f"{rate(sum(not r['chosen'] for r in rs), len(rs))} | "
                         f"{rate(sum(_noise_ok(r) for r in rs), len(rs))} | {rate(sum(est), len(est))} |")
        bad = [r for r in noise if not _noise_ok(r)]
        if bad:
            lines += ["", "| misses: layout | seed | f | mismatch | chosen | outliers |", "|---|---|---|---|---|---|"]
            for r in bad[:20]:
                lines.append(f"| {r['label']} | {r['seed']} | {r['noise_factor']:.2f} | {r['mismatch']} | "
                             f"{', '.join(r['chosen']) or '—'} | {', '.join(r['outliers']) or '—'} |")
    return lines


def summarize(results: list[dict], meta: dict) -> str:
    eff = [r for r in results if r["category"] not in ("null", "aliased", "outlier", "noise")]
    single = [r for r in eff if len(r["planted"]) == 1]
    two = [r for r in eff if len(r["planted"]) == 2]
    null = [r for r in results if r["category"] == "null"]
    ali = [r for r in results if r["category"] == "aliased"]
    first = sum(1 for r in single if r["chosen"][:1] == list(r["planted"]))
    found_two = sum(1 for r in two if all(p in r["chosen"] for p in r["planted"]))
    est = [ok for r in eff for ok in r["within_3u"].values()]
    false_alarm = sum(1 for r in null if r["mismatch"])
    spurious_null = sum(1 for r in null if r["chosen"])
    lines = [
        "# Mismatch locator: detection rates (bench/diagnose_benchmark.py)",
        "",
        f"Measured {meta['date']}, {meta['sets']} data sets in {meta['seconds']:.0f} s "
        f"(diagnose alone: median {meta['median_diag_s'] * 1000:.0f} ms per set).  Simulated CMM: "
        "Forbes 2025 Table 3 MPE1 (the same model diagnose uses); alpha = 0.01, Bonferroni over the "
        "candidates of each step; planted size = SNR x u(effect in that design), "
        f"SNR ~ U[{SNR_LO:g}, {SNR_HI:g}] for every effect (masked sets: the larger effect x {MASK_FACTOR:g}), "
        "random sign/direction, random seeds.",
        "",
        "| criterion | measured | target |",
        "|---|---|---|",
        f"| planted effect named first (single-effect sets) | {rate(first, len(single))} | ≥ 95 % |",
        f"| every planted effect found (two-effect sets) | {rate(found_two, len(two))} | all |",
        f"| estimate within 3 u of the truth (found effects) | {rate(sum(est), len(est))} | ≥ 95 % |",
        f"| second-edition candidates (straightness, reversal, thermal gradient, probe lobing, periodic; docs/recordings.md section 7) named first | "
        f"{rate(sum(1 for r in single if set(r['planted']) <= NEW and r['chosen'][:1] == list(r['planted'])), sum(1 for r in single if set(r['planted']) <= NEW))} | ≥ 95 % |",
        f"| second-edition candidates: estimate within 3 u of the truth | "
        f"{rate(sum(ok for r in eff for k, ok in r['within_3u'].items() if k in NEW), sum(1 for r in eff for k in r['within_3u'] if k in NEW))} | ≥ 95 % |",
        f"| null sets raising a mismatch (nominal: alpha = 1 %, binomial s.e. "
        f"{100 * math.sqrt(0.01 * 0.99 / max(len(null), 1)):.1f} %) | {rate(false_alarm, len(null))} | ≤ 2 % |",
        f"| null sets with an effect chosen (named at adjusted p < alpha/100, docs/recordings.md section 7) | "
        f"{rate(spurious_null, len(null))} | none |",
        f"| null sets with an effect only indicated (adjusted p between alpha/100 and alpha, not applied) | "
        f"{rate(sum(bool(r.get('indicated')) for r in null), len(null))} | — |",
        f"| aliased designs reported as aliased (naming the look-alike and a second probe offset) | "
        f"{rate(sum(r['alias_reported'] for r in ali), len(ali))} | all |",
        f"| null sets raising a mismatch by the omnibus gate / the targeted gate (alpha/2 each) | "
        f"{rate(sum(r['gate'] in ('omnibus', 'both') for r in null), len(null))} / "
        f"{rate(sum(r['gate'] in ('targeted', 'both') for r in null), len(null))} | ≤ 1 % each |",
        f"| null sets reporting an outlier / a noise scale | {rate(sum(bool(r['outliers']) for r in null), len(null))} / "
        f"{rate(sum(r['noise_scale'] is not None for r in null), len(null))} | — |",
        f"| effect sets (single and two-effect) explained after the refit (p_after >= alpha) | "
        f"{rate(sum(bool(r['explained']) for r in eff), len(eff))} | — |",
        *special_rows(results),
        "",
        "## By concealment",
        "",
        "| concealment | sets | named first / all found | within 3 u | max single-record shift (median, 90 %) | chi2 excess in sd (median) |",
        "|---|---|---|---|---|---|",
    ]
    for cat in ("small", "subset", "aliased-unless", "masked"):
        rs = [r for r in eff if r["category"] == cat]
        if not rs:
            continue
        ok = sum(1 for r in rs if (r["chosen"][:1] == list(r["planted"]) if len(r["planted"]) == 1
                                   else all(p in r["chosen"] for p in r["planted"])))
        w = [v for r in rs for v in r["within_3u"].values()]
        vis = [r["max_record_z"][0] for r in rs]
        exc = [r["chi2_excess_sd"] for r in rs]
        lines.append(f"| {cat} | {len(rs)} | {rate(ok, len(rs))} | {rate(sum(w), len(w))} | "
                     f"{np.median(vis):.1f} σ, {np.quantile(vis, 0.9):.1f} σ | {np.median(exc):.1f} |")
    lines += ["", "\"max single-record shift\": the largest |planted shift| / u over the records of a set, u the "
              "record's standard uncertainty under the simulation (what one would see looking at records "
              "one by one; the largest of 100 pure-noise records is about 2.6 σ anyway).  Effects of a kind "
              "the simulation already allows as a shared random error (scale, squareness, probe radius and "
              "offsets, rotation processes) must exceed that allowance to be a mismatch at all, so their "
              "longest records show them; only effects without such a counterpart (temperature, time) or "
              "spread over many directions can hide below about 2-3 σ in every record (category small).",
              "", "## By effect (every set where it was planted)", "",
              "| effect | sets | found | named first (single) | within 3 u |", "|---|---|---|---|---|"]
    for name in fx.NAMES:
        rs = [r for r in eff if name in r["planted"]]
        if not rs:
            continue
        found = sum(1 for r in rs if name in r["chosen"])
        sg = [r for r in rs if len(r["planted"]) == 1]
        nf = sum(1 for r in sg if r["chosen"][:1] == [name])
        w = [r["within_3u"][name] for r in rs if name in r["within_3u"]]
        lines.append(f"| {name} | {len(rs)} | {rate(found, len(rs))} | {rate(nf, len(sg))} | {rate(sum(w), len(w))} |")
    lines += ["", "## By scenario", "", "| scenario | concealment | sets | named first / all found |",
              "|---|---|---|---|"]
    for label in dict.fromkeys(r["label"] for r in results):
        rs = [r for r in results if r["label"] == label]
        cat = rs[0]["category"]
        if cat == "null":
            k = sum(1 for r in rs if not r["mismatch"])
            what = f"quiet {rate(k, len(rs))}"
        elif cat == "aliased":
            what = f"reported aliased {rate(sum(r['alias_reported'] for r in rs), len(rs))}"
        elif cat == "outlier":
            what = f"outlier named first, no effect {rate(sum(_outlier_ok(r) for r in rs), len(rs))}"
        elif cat == "noise":
            what = f"noise_scale, no effect {rate(sum(_noise_ok(r) for r in rs), len(rs))}"
        else:
            k = sum(1 for r in rs if (r["chosen"][:1] == list(r["planted"]) if len(r["planted"]) == 1
                                      else all(p in r["chosen"] for p in r["planted"])))
            what = rate(k, len(rs))
        lines.append(f"| {label} | {cat} | {len(rs)} | {what} |")
    lines += special_sections(results)
    if meta.get("power"):
        lines += ["", "## Power curve: the two gates against the omnibus gate alone and the oracle", "",
                  "Single-effect sets (all scenarios above, in turn) at a fixed aggregate signal SNR (the "
                  "planted effect's Mahalanobis length in its own GLS standard uncertainties).  Omnibus "
                  "alone: the first edition's gate, p_before < alpha.  Two gates (docs/recordings.md "
                  "section 7): omnibus or targeted (Bonferroni over the candidates of the first step), "
                  "alpha/2 each.  Oracle: a test of the planted effect's own columns at alpha (noncentral "
                  "chi-square, averaged over the same sets; 1 column: 95 % at 4.2 σ).  Named first: chosen "
                  "first (adjusted p < alpha/100); named or indicated: chosen first, or the indicated effect "
                  "when nothing was chosen.  The periodic candidates pay for the scan of their period "
                  "(look-elsewhere factor M, docs/diagnose.md section 6): their sets are also shown apart.", "",
                  "| SNR | sets | omnibus alone | two gates | named first | named or indicated first | oracle | "
                  "two gates: periodic sets / the others |",
                  "|---|---|---|---|---|---|---|---|"]
        for snr, (n, om, mm, nf, ni, orc, n_scan, mm_scan) in meta["power"].items():
            lines.append(f"| {snr:g} | {n} | {rate(om, n)} | {rate(mm, n)} | {rate(nf, n)} | {rate(ni, n)} | "
                         f"{100 * orc:.1f} % | {rate(mm_scan, n_scan)} / {rate(mm - mm_scan, n - n_scan)} |")
    misses = [r for r in single if r["chosen"][:1] != list(r["planted"])] + \
             [r for r in two if not all(p in r["chosen"] for p in r["planted"])]
    if misses:
        lines += ["", "## Misses", "", "| scenario | seed | planted (SNR) | chosen |", "|---|---|---|---|"]
        for r in misses:
            pl = ", ".join(f"{k} ({v['snr']:.1f})" for k, v in r["planted"].items())
            lines.append(f"| {r['label']} | {r['seed']} | {pl} | {', '.join(r['chosen']) or '— (no mismatch)' if r['mismatch'] else '— (no mismatch)'} |")
    return "\n".join(lines) + "\n"


def oracle_power(snr: float, df: int, alpha: float = ALPHA) -> float:
    """Power of the test that knows the effect (its df columns) at level alpha: the noncentral
    chi-square with noncentrality SNR^2 beyond the central quantile."""
    from scipy.stats import chi2, ncx2

    return float(ncx2.sf(chi2.isf(alpha, df), df, snr * snr))


def power_curve(snrs, per: int, seed0: int) -> dict:
    """Per SNR: sets, omnibus test alone (first edition, p_before < alpha), the two gates of
    section 7, planted effect named first, named or indicated first, and the oracle's mean power
    over the same sets."""
    global SNR_LO, SNR_HI
    lo, hi = SNR_LO, SNR_HI
    out = {}
    pool = [s for s in scenarios() if len(s.effects) == 1]
    try:
        for snr in snrs:
            SNR_LO = SNR_HI = snr
            n = om = mm = nf = ni = n_scan = mm_scan = 0
            orc = 0.0
            for q in range(per):
                sc = pool[(q * 7 + int(snr)) % len(pool)]
                r = run_set(sc, seed0 + 1000 * int(snr * 10) + q)
                n += 1
                om += r["omnibus_alone"]
                mm += r["mismatch"]
                if set(sc.effects) <= set(fx.PERIODIC):     # a scanned period: its look-elsewhere cost
                    n_scan += 1
                    mm_scan += r["mismatch"]
                nf += r["chosen"][:1] == list(r["planted"])
                ni += (r["chosen"] or r["indicated"])[:1] == list(r["planted"])
                orc += oracle_power(snr, next(iter(r["df"].values())))
            out[snr] = (n, om, mm, nf, ni, orc / max(n, 1), n_scan, mm_scan)
    finally:
        SNR_LO, SNR_HI = lo, hi
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", type=int, default=0, help="only N effect sets and N null sets")
    ap.add_argument("--reps", type=int, default=6, help="seeds per effect scenario (default 6)")
    ap.add_argument("--nulls", type=int, default=1002, help="null sets (default 1002)")
    ap.add_argument("--aliased", type=int, default=10, help="aliased-design sets (default 10)")
    ap.add_argument("--power", type=int, default=200, help="sets per SNR of the power curve (0: skip)")
    ap.add_argument("--outliers", type=int, default=None, help="sets with one gross outlier (default 150; quick: 0)")
    ap.add_argument("--noise", type=int, default=None, help="sets with inflated noise (default 240; quick: 0)")
    ap.add_argument("--seed", type=int, default=20250101)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    ap.add_argument("--json", action="store_true", help="also write every data set (diagnose_benchmark*.json)")
    ap.add_argument("--only", default=None, metavar="PREFIX",
                    help="only the effect scenarios planting a candidate whose name starts with PREFIX (e.g. "
                         "periodic; with --reps for more seeds), no null, outlier, noise or power sets; "
                         "written to diagnose_rates_PREFIX.md")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rng = np.random.default_rng(args.seed)
    jobs = []
    scs = scenarios(second_edition=not args.quick)
    if args.only:
        scs = [sc for sc in scs if any(e.startswith(args.only) for e in sc.effects)]
        if not scs:
            ap.error(f"--only {args.only}: no scenario plants such a candidate")
        args.nulls = args.aliased = args.outliers = args.noise = args.power = 0
    if args.quick:
        stride = 7 if len(scs) % 7 else 11         # spread over the categories
        eff = [scs[(q * stride) % len(scs)] for q in range(args.quick)]
        jobs += [(s, int(rng.integers(2**31))) for s in eff]
        jobs += [(NULLS[q % len(NULLS)], int(rng.integers(2**31))) for q in range(args.quick)]
        jobs += [(ALIASED[q % len(ALIASED)], int(rng.integers(2**31))) for q in range(2)]
    else:
        jobs += [(s, int(rng.integers(2**31))) for s in scs for _ in range(args.reps)]
        jobs += [(NULLS[q % len(NULLS)], int(rng.integers(2**31))) for q in range(args.nulls)]
        jobs += [(ALIASED[q % len(ALIASED)], int(rng.integers(2**31))) for q in range(args.aliased)]
    n_out = args.outliers if args.outliers is not None else (0 if args.quick else 150)
    n_noise = args.noise if args.noise is not None else (0 if args.quick else 240)
    jobs += [(OUTLIERS[q % len(OUTLIERS)], int(rng.integers(2**31))) for q in range(n_out)]
    jobs += [(NOISE[q % len(NOISE)], int(rng.integers(2**31))) for q in range(n_noise)]
    results = []
    for q, (sc, seed) in enumerate(jobs, start=1):
        results.append(run_set(sc, seed))
        if q % 50 == 0:
            print(f"  {q}/{len(jobs)} sets, {time.perf_counter() - t0:.0f} s", flush=True)
    power = {}
    if args.power and not args.quick:
        power = power_curve((3.0, 4.0, 4.5, 5.0, 5.5, 6.0, 7.0, 8.0, 10.0), args.power, args.seed + 7)
    meta = {"date": time.strftime("%Y-%m-%d"), "sets": len(results), "seconds": time.perf_counter() - t0,
            "median_diag_s": float(np.median([r["seconds"] for r in results])), "power": power}
    table = summarize(results, meta)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = ("diagnose_rates" if not args.quick else f"diagnose_rates_quick{args.quick}") + \
        (f"_{args.only}" if args.only else "")
    (out / f"{name}.md").write_text(table, encoding="utf-8")
    if args.json:
        (out / f"{name.replace('rates', 'benchmark')}.json").write_text(
            json.dumps({"meta": {k: v for k, v in meta.items() if k != "power"},
                        "power": {str(k): v for k, v in power.items()}, "sets": results}, indent=1),
            encoding="utf-8")
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
