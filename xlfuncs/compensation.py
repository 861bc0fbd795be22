"""The locator's findings fed back into the uncertainty model (``cmmwb calibrate``).

An effect the locator names (``docs/recordings.md`` section 4) with its estimate b and standard
uncertainty u(b) enters the task in one of two ways, named in the output:

``compensate``  the coordinates are corrected by the estimated effect (the records rewritten:
                measured - X b); what remains of it is the uncertainty of the correction, so the
                influence factor the effect belongs to keeps only u(b): the factor's standard
                deviation becomes the RMS of u(b) over the factor's parameters (scale: sigma_S =
                u(s); the three per-axis scales: sigma_Sa, when all three are corrected; the three
                squarenesses: sigma_Q; probe_qualification: sigma_PQ; probe_radius: sigma_P0).
                A factor of which only some parameters were corrected keeps its spread (the others
                still carry it).
``factor``      the coordinates stay as measured; the known error is an additional influence
                with standard deviation sqrt(b^2 + u(b)^2) (a systematic error not corrected,
                treated as a standard uncertainty, as the MPE approach of Wojtyla/Plowucha 2023
                treats the E_L,MPE), added in quadrature to its factor's standard deviation (the
                largest over the factor's parameters).

Effects outside the six factors (angular motions, drifts, thermal, straightness, ...) can be
compensated (the coordinates corrected) but their u(b) has no parameter of the six factors to go
to; they are listed in the notes of the fitted task and ``factor`` refuses them.

``thermal_expansion`` (the artefact's alpha off the alpha_c the CMM corrects with, Delta alpha in
10^-6/K) belongs to the factor W when the task describes the artefact (``[workpiece]``,
docs/workpiece.md): ``compensate`` makes the CMM correct with the artefact's alpha = alpha_c +
Delta alpha and keeps u(alpha) = u(Delta alpha) (:func:`fed_back_workpiece`); ``factor`` adds
Delta alpha^2 + u^2 to u^2(alpha).  Without ``[workpiece]`` it stays outside the factors, as before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from . import pointcloud as pc
from .errors import ModelError
from .model.workpiece import Workpiece

MODES = ("compensate", "factor")

#: effect -> (hyper-parameter of its factor, the factor's group of effects)
EFFECT_FACTOR = {
    "scale": ("sigma_S_ppm", ("scale",)),
    "scale_x": ("sigma_Sa_ppm", ("scale_x", "scale_y", "scale_z")),
    "scale_y": ("sigma_Sa_ppm", ("scale_x", "scale_y", "scale_z")),
    "scale_z": ("sigma_Sa_ppm", ("scale_x", "scale_y", "scale_z")),
    "squareness_xy": ("sigma_Q_ppm", ("squareness_xy", "squareness_xz", "squareness_yz")),
    "squareness_xz": ("sigma_Q_ppm", ("squareness_xy", "squareness_xz", "squareness_yz")),
    "squareness_yz": ("sigma_Q_ppm", ("squareness_xy", "squareness_xz", "squareness_yz")),
    "probe_radius": ("sigma_P0_um", ("probe_radius",)),
    "probe_qualification": ("sigma_PQ_um", ("probe_qualification",)),
}
#: the effect of the factor W, when the task has a [workpiece] (docs/workpiece.md)
WORKPIECE_EFFECT = {"thermal_expansion": ("u_alpha_ppm_per_K", ("thermal_expansion",))}


@dataclass
class Finding:
    """One named effect: its parameters' estimates and standard uncertainties (the effect's unit)."""

    name: str
    estimate: list[float]
    u: list[float]
    unit: str


@dataclass
class Change:
    parameter: str
    before: float
    after: float
    effects: list[str]
    how: str


def absorbed(names) -> set[str]:
    """Hyper-parameters whose factor the fixed effects ``names`` take over: a factor all of whose
    parameters are fixed effects (scale -> sigma_S_ppm; scale_x, _y, _z -> sigma_Sa_ppm; the three
    squarenesses -> sigma_Q_ppm; probe_qualification -> sigma_PQ_um; probe_radius -> sigma_P0_um).
    The effects' estimates are then the machine's draw of that factor, so they are estimated with
    the factor left out of the covariance (else u(b) would count the factor's spread again)."""
    got = set(names)
    table = EFFECT_FACTOR | WORKPIECE_EFFECT
    return {table[n][0] for n in got if n in table and set(table[n][1]) <= got}


def feed_back(params: pc.Parameters, findings: list[Finding], mode: str, *,
              workpiece: Workpiece | None = None) -> tuple[pc.Parameters, list[Change], list[str]]:
    """The task's parameters with the findings fed back (module docstring): (parameters, the
    changes, notes on what could not be represented).  ``workpiece``: the artefact of the task's
    [workpiece] (``thermal_expansion`` then goes to u(alpha), the factor W)."""
    if mode not in MODES:
        raise ModelError(f"unknown mode {mode!r}: choose one of {', '.join(MODES)}")
    table = EFFECT_FACTOR | (WORKPIECE_EFFECT if workpiece is not None else {})
    by_param: dict[str, list[Finding]] = {}
    notes: list[str] = []
    for f in findings:
        if f.name in table:
            by_param.setdefault(table[f.name][0], []).append(f)
        elif mode == "factor":
            raise ModelError(f"{f.name} is not one of the six influence factors' parameters: it cannot be "
                             "added as a factor; compensate it instead")
        else:
            notes.append(f"{f.name} compensated in the coordinates ({_fmt(f)}); its u is outside the six "
                         "factors and not part of V_X")
    values = {k: float(getattr(params, k)) for k in params.__dataclass_fields__}
    changes = []
    for p, fs in by_param.items():
        before = values[p]
        group = set(table[fs[0].name][1])
        got = {f.name for f in fs}
        us = [u for f in fs for u in f.u if u is not None]
        bs = [b for f in fs for b in f.estimate if b is not None]
        if mode == "compensate":
            if got >= group and us:
                after = math.sqrt(float(np.mean(np.square(us))))
                how = "compensated: sigma = RMS of the corrections' u"
            else:
                after = before
                how = ("compensated in the coordinates; the factor keeps its spread (not all of "
                       + ", ".join(sorted(group)) + " corrected)")
        else:
            add = max(b * b + u * u for b, u in zip(bs, us))
            after = math.sqrt(before * before + add)
            how = "added as an influence factor: sigma^2 + max(b^2 + u(b)^2)"
        values[p] = after
        changes.append(Change(p, before, after, sorted(got), how))
    return pc.Parameters(**values), changes, notes


def fed_back_workpiece(workpiece: Workpiece | None, findings: list[Finding], mode: str) -> Workpiece | None:
    """The artefact after ``thermal_expansion`` is compensated (module docstring): the CMM corrects
    with the artefact's own alpha = alpha_c + Delta alpha (None: nothing to change)."""
    if workpiece is None or mode != "compensate":
        return None
    found = [f for f in findings if f.name in WORKPIECE_EFFECT and f.estimate and f.estimate[0] is not None]
    if not found:
        return None
    alpha = workpiece.alpha_c + float(found[0].estimate[0])
    return replace(workpiece, alpha_ppm_per_K=alpha, alpha_corr_ppm_per_K=alpha, corrected=True)


def _fmt(f: Finding) -> str:
    pairs = [f"{b:.4g} ± {u:.2g}" for b, u in zip(f.estimate, f.u) if b is not None and u is not None]
    return ", ".join(pairs) + f" {f.unit}"


def corrected_records(rec, prep, X_eff: np.ndarray, beta: np.ndarray):
    """The recordings with the effects X_eff beta (µm, per observation row of ``prep``) removed
    from the measured lengths or coordinates: the compensated coordinates."""
    delta_um = X_eff @ beta if X_eff.shape[1] else np.zeros(len(prep.r_um))
    if prep.design.kind == "length":
        return replace(rec, measured_mm=rec.measured_mm - delta_um / 1000.0)
    dims = prep.design.dims
    X = rec.X_mm.copy()
    X[:, :dims] -= delta_um.reshape(rec.n, dims) / 1000.0
    return replace(rec, X_mm=X)
