"""Simulated validation sets (``cmmwb simulate --validation``, docs/validate.md): calibrated
workpieces measured by one CMM drawn from the Forbes 2025 model (the generative model of
:mod:`xlfuncs.locator.simulate`: the machine's own errors factor by factor, and the planted effects
of docs/recordings.md section 4), with their certificates; the check of the check.

Workpieces (machine coordinates in mm, the working volume of :data:`simulate.VOLUME_MM`):

``ballplate``  5 x 5 ball plate, pitch 100 mm, in the xy plane at z = 150 mm turned by 30 deg;
               every distance between two ball centres (300 lengths), probe 1
``stepgauge``  step gauge of Forbes 2025 section 7 with 21 steps along x, y and the xy diagonal
               (three placements): every face from the first (41 lengths each), both probes
``ring``       ring gauges of 25 mm and 100 mm bore, 16 points on the bore at mid-height with
               their normals: the least-squares diameter (a ``characteristic`` task's own fit)
``sphere``     two reference spheres of 25 mm, 25 points each (pole and three rings of eight):
               their diameters and the distance between their centres

One machine measures everything: the systematic errors (PQ, S, ET, ER, P and the planted effects)
are one draw over every probing of every workpiece; every run re-probes with its own
repeatability.  The certificate's value is the true value plus a draw of the calibration error
(u_cal = U_cal/k_cal, one per characteristic, the same in every run).

numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import characteristics as ch
from . import pointcloud as pc
from .errors import ModelError
from .locator import simulate as sm

WORKPIECES = ("ballplate", "stepgauge", "ring", "sphere")
#: the certificates' expanded uncertainty (k = 2): a + b L in µm with L in m, per workpiece
CERTIFICATE_UM = {"ballplate": (0.3, 0.5), "stepgauge": (0.2, 0.5), "ring": (0.15, 0.0),
                  "sphere": (0.1, 0.0), "sphere distance": (0.3, 0.5)}
K_CAL = 2.0
#: the probes when the task gives none: two styli at +-20 mm in y, 30 mm below the head
DEFAULT_PROBES = (pc.Probe("P1", (0.0, 20.0, -30.0)), pc.Probe("P2", (0.0, -20.0, -30.0)))


@dataclass(frozen=True)
class Length:
    """A length characteristic: the distance between probings ``i`` and ``j`` of the set."""

    label: str
    workpiece: str
    i: int
    j: int


@dataclass
class ValidationSet:
    """The probings of every workpiece (one point set), the length characteristics (a pointcloud
    task's distances) and the fitted ones (a characteristic task's features and characteristics
    over the probings ``fit_points``)."""

    probes: tuple[pc.Probe, ...]
    X: np.ndarray                     # (m, 3) true probed positions, mm
    N: np.ndarray                     # (m, 3) outward normals
    k: np.ndarray                     # (m,) probe index
    ids: list[str]
    workpiece_of_point: list[str]
    lengths: list[Length] = field(default_factory=list)
    fit_points: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    features: list[ch.FeatureSpec] = field(default_factory=list)     # indices into fit_points
    characteristics: list[ch.CharacteristicSpec] = field(default_factory=list)
    workpiece_of_char: dict[str, str] = field(default_factory=dict)

    @property
    def labels(self) -> list[str]:
        return [c.label for c in self.lengths] + [c.name for c in self.characteristics]


def _add(vs_parts: dict, workpiece: str, X, N, k, ids) -> np.ndarray:
    start = len(vs_parts["X"])
    vs_parts["X"].extend(np.asarray(X, float))
    vs_parts["N"].extend(np.asarray(N, float))
    vs_parts["k"].extend(np.asarray(k, int))
    vs_parts["ids"].extend(ids)
    vs_parts["wp"].extend([workpiece] * len(ids))
    return np.arange(start, start + len(ids))


def build(workpieces=("ballplate", "stepgauge"), probes: tuple[pc.Probe, ...] | None = None) -> ValidationSet:
    """The workpieces of the module docstring, placed in the volume; ``probes``: the machine's
    probes (the step gauge's right faces use the second when there are two)."""
    probes = tuple(probes) if probes else DEFAULT_PROBES
    unknown = [w for w in workpieces if w not in WORKPIECES]
    if unknown or not workpieces:
        raise ModelError(f"unknown workpiece {unknown[0]!r}; choose from {', '.join(WORKPIECES)}" if unknown
                         else "no workpiece")
    parts: dict[str, list] = {"X": [], "N": [], "k": [], "ids": [], "wp": []}
    lengths: list[Length] = []
    fit_idx: list[int] = []
    features, chars, wp_char = [], [], {}
    if "ballplate" in workpieces:
        L = sm.ballplate(probes[:1], passes=1)
        ids = [f"BP.{i.split('-')[0]}" for i in L.ids]
        idx = _add(parts, "ballplate", L.X, np.tile([0.0, 0.0, 1.0], (len(ids), 1)), np.zeros(len(ids), int), ids)
        order = np.argsort(ids, kind="stable")
        for a in range(len(order)):
            for b in range(a + 1, len(order)):
                i, j = idx[order[a]], idx[order[b]]
                lengths.append(Length(f"{ids[order[a]]}→{ids[order[b]]}", "ballplate", int(i), int(j)))
    if "stepgauge" in workpieces:
        L = sm.stepgauge(probes[:2], steps=21)
        names = []
        for q in range(len(L.X)):
            pos = next(L.ids[a].split("-")[0] for a in range(L.n) if q in (L.I[a], L.J[a]))
            names.append(pos)
        ids, count = [], {}
        for q, pos in enumerate(names):
            count[pos] = count.get(pos, 0) + 1
            ids.append(f"SG{pos}.F{count[pos]}")
        idx = _add(parts, "stepgauge", L.X, L.N, L.k, ids)
        for a in range(L.n):
            i, j = idx[L.I[a]], idx[L.J[a]]
            lengths.append(Length(f"{ids[L.I[a]]}→{ids[L.J[a]]}", "stepgauge", int(i), int(j)))
    if "ring" in workpieces:
        for name, d, centre in (("ring25", 25.0, (300.0, 250.0, 120.0)), ("ring100", 100.0, (650.0, 500.0, 80.0))):
            phi = np.arange(16) * 2 * math.pi / 16
            e = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(16)])
            X = np.asarray(centre) + 0.5 * d * e
            idx = _add(parts, "ring", X, -e, np.zeros(16, int), [f"{name}.{q + 1}" for q in range(16)])
            start = len(fit_idx)
            fit_idx += idx.tolist()
            features.append(ch.FeatureSpec(name, "circle", tuple(range(start, start + 16)), circle_plane="xy"))
            chars.append(ch.CharacteristicSpec(f"{name}_D", "diameter", (name,)))
            wp_char[f"{name}_D"] = "ring"
    if "sphere" in workpieces:
        dirs = [np.array([0.0, 0.0, 1.0])]
        for el in (60.0, 30.0, 0.0):
            for az in range(0, 360, 45):
                a, e_ = math.radians(az + (22.5 if el == 30.0 else 0.0)), math.radians(el)
                dirs.append(np.array([math.cos(e_) * math.cos(a), math.cos(e_) * math.sin(a), math.sin(e_)]))
        D = np.array(dirs)
        for name, centre in (("S1", (200.0, 150.0, 100.0)), ("S2", (800.0, 600.0, 350.0))):
            idx = _add(parts, "sphere", np.asarray(centre) + 12.5 * D, D, np.zeros(len(D), int),
                       [f"{name}.{q + 1}" for q in range(len(D))])
            start = len(fit_idx)
            fit_idx += idx.tolist()
            features.append(ch.FeatureSpec(name, "sphere", tuple(range(start, start + len(D)))))
            chars.append(ch.CharacteristicSpec(f"{name}_D", "diameter", (name,)))
            wp_char[f"{name}_D"] = "sphere"
        chars.append(ch.CharacteristicSpec("S1_S2_distance", "distance", ("S1", "S2")))
        wp_char["S1_S2_distance"] = "sphere"
    return ValidationSet(probes, np.array(parts["X"]), np.array(parts["N"]), np.array(parts["k"]), parts["ids"],
                         parts["wp"], lengths, np.array(fit_idx, dtype=int), features, chars, wp_char)


def true_values(vs: ValidationSet) -> dict[str, float]:
    """The true value (mm) of every characteristic: the artefact as made."""
    out = {c.label: float(np.linalg.norm(vs.X[c.j] - vs.X[c.i])) for c in vs.lengths}
    if vs.characteristics:
        jf = ch.fit_features(vs.X[vs.fit_points], vs.N[vs.fit_points], vs.features)
        for r in ch.evaluate(jf, {}, vs.characteristics):
            out[r.name] = r.value
    return out


def certificate_U(vs: ValidationSet, values: dict[str, float]) -> dict[str, float]:
    """U_cal (µm, k_cal = 2) of every characteristic: :data:`CERTIFICATE_UM` a + b L."""
    out = {}
    for c in vs.lengths:
        a, b = CERTIFICATE_UM[c.workpiece]
        out[c.label] = a + b * values[c.label] / 1000.0
    for c in vs.characteristics:
        a, b = CERTIFICATE_UM["sphere distance" if c.type == "distance" else vs.workpiece_of_char[c.name]]
        out[c.name] = a + b * values[c.name] / 1000.0
    return out


def model_U(vs: ValidationSet, params: pc.Parameters, k: float = 2.0) -> dict[str, float]:
    """The model's U = k u (µm) of every characteristic at the true geometry: a length's u from
    G V_X G^T (Forbes 2025 eq. 29), a fitted one's from its sensitivities over V_X (the
    characteristic kind's evaluation)."""
    from .record_covariance import record_covariance

    out = {}
    if vs.lengths:
        cloud = pc.PointCloud(vs.X, vs.N, vs.k, vs.probes, tuple(vs.ids))
        I = np.array([c.i for c in vs.lengths])
        J = np.array([c.j for c in vs.lengths])
        var = np.diag(record_covariance(cloud, params, I, J))
        for c, v in zip(vs.lengths, var):
            out[c.label] = k * math.sqrt(v)
    if vs.characteristics:
        f = vs.fit_points
        cloud = pc.PointCloud(vs.X[f], vs.N[f], vs.k[f], vs.probes, tuple(vs.ids[i] for i in f))
        V = pc.V_X_components(cloud, params)
        jf = ch.fit_features(vs.X[f], vs.N[f], vs.features)
        for r in ch.evaluate(jf, {}, vs.characteristics, V):
            out[r.name] = k * r.u
    return out


@dataclass
class Measured:
    """One validation run of the set: per characteristic and run the measured value (mm)."""

    values: dict[str, list[float]]            # label -> measured value per run
    calibrated: dict[str, float]
    U_cal: dict[str, float]
    truth: dict[str, float]
    X_indicated: list[np.ndarray]              # per run, the indicated probings (mm)


def measure(vs: ValidationSet, params: pc.Parameters, planted: dict | None = None, seed: int | None = 0,
            runs: int = 2) -> Measured:
    """The set measured ``runs`` times by one CMM drawn from ``params`` with the ``planted``
    effects (docs/recordings.md section 4; simulate's definitions), and its certificates."""
    if runs < 1:
        raise ModelError("runs must be at least 1")
    rng = np.random.default_rng(seed)
    m = len(vs.X)
    L = sm.Layout("length", "validation", vs.probes, vs.X, vs.N, vs.k, [f"q{i}" for i in range(m)],
                  ["validation"] * m, np.zeros(m))
    planted = sm.check_effects(planted or {}, vs.probes)
    for name in planted:
        if name.startswith("thermal") or name.endswith("_drift"):
            raise ModelError(f"{name}: temperatures and times are not simulated in validation sets")
    systematic = sm.model_errors(vs.X, vs.N, vs.k, vs.probes, replace(params, sigma_R_um=0.0), rng)
    systematic += sm.planted_probing(L, planted, np.zeros(m), np.full(m, 20.0))
    truth = true_values(vs)
    U_cal = certificate_U(vs, truth)
    calibrated = {lab: truth[lab] + 1e-3 * (U_cal[lab] / K_CAL) * rng.standard_normal() for lab in vs.labels}
    values: dict[str, list[float]] = {lab: [] for lab in vs.labels}
    Xs = []
    for _ in range(runs):
        delta = systematic + params.sigma_R_um * rng.standard_normal((m, 3))
        Xi = vs.X + 1e-3 * delta
        Xs.append(Xi)
        for c in vs.lengths:
            values[c.label].append(float(np.linalg.norm(Xi[c.j] - Xi[c.i])))
        if vs.characteristics:
            f = vs.fit_points
            jf = ch.fit_features(Xi[f], vs.N[f], vs.features)
            for r in ch.evaluate(jf, {}, vs.characteristics):
                values[r.name].append(r.value)
    return Measured(values, calibrated, U_cal, truth, Xs)


def rows_of(vs: ValidationSet, meas: Measured, U_model: dict[str, float], k: float = 2.0):
    """The validation rows of a measured set (one per characteristic and run; unit mm, U in µm)
    and the probed points of its length rows: the input of :func:`xlfuncs.validation.validate`."""
    from .validation import Geometry, Rows

    labels, wps, runs, y, y_cal, U_cal, U = [], [], [], [], [], [], []
    geo_rows, I, J = [], [], []
    by_len = {c.label: c for c in vs.lengths}
    for r in range(len(meas.X_indicated)):
        for lab in vs.labels:
            if lab in by_len:
                c = by_len[lab]
                geo_rows.append(len(labels))
                I.append(c.i)
                J.append(c.j)
                wps.append(c.workpiece)
            else:
                wps.append(vs.workpiece_of_char[lab])
            labels.append(lab)
            runs.append(str(r + 1))
            y.append(meas.values[lab][r])
            y_cal.append(meas.calibrated[lab])
            U_cal.append(meas.U_cal[lab])
            U.append(U_model[lab])
    n = len(labels)
    rows = Rows(tuple(labels), tuple(wps), tuple(runs), np.array(y), np.ones(n, dtype=int), np.full(n, np.nan),
                np.array(y_cal), np.array(U_cal), np.full(n, K_CAL), np.array(U), np.full(n, float(k)),
                np.full(n, 1000.0), ("mm",) * n, ("µm",) * n, tuple(range(2, n + 2)))
    geo = None
    if geo_rows:
        I_, J_ = np.array(I), np.array(J)
        pid = [p.id for p in vs.probes]
        geo = Geometry(np.array(geo_rows), vs.X[I_], vs.X[J_], vs.N[I_], vs.N[J_],
                       np.array([vs.probes[q].offset_mm for q in vs.k[I_]], dtype=float),
                       np.array([vs.probes[q].offset_mm for q in vs.k[J_]], dtype=float),
                       tuple(pid[q] for q in vs.k[I_]), tuple(pid[q] for q in vs.k[J_]))
    return rows, geo
