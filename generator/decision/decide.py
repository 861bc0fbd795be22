"""The conformity decisions of a task as data: the ``[decision]`` table and its tolerances read
and validated, and the decisions of the results JSON.

Every task kind hands its results over as records (:class:`generator.quantities.Quantity`: value,
u, U, where they sit in the workbook); a ``[[decision.tolerances]]`` entry names one of them by
the kind's keys (:class:`generator.quantities.ToleranceKeys`: a budget characteristic's name, a
distance's two point ids, a feature parameter) and gives its specification limits; a kind whose
results carry their own tolerances (a drawing's characteristics) has them decided without such
entries.  The decision rule of ``[decision]`` turns value, U and limits into a decision
(:mod:`xlfuncs.conformity`, JCGM 106:2012 and ISO 14253-1:2017).  The ``Decision`` sheet that
computes the same with live formulas is :mod:`generator.decision.sheet`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from cmmwb.xlfuncs import conformity as cf
from cmmwb.xlfuncs import dof
from cmmwb.xlfuncs import global_risk as gr
from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.limits import MAX_COORDINATE_MM
from cmmwb.xlfuncs.statement import statement

from ..errors import InputError
from ..quantities import Quantity, ToleranceKeys
from ..taskfile import check_keys

SECTION = "decision"
TOL_SECTION = "[[decision.tolerances]]"
RULE_KEYS = {"rule", "r", "max_pfa", "k", "k_from_dof", "tolerances"}
LIMIT_KEYS = {"nominal_mm", "tol_mm", "lsl_mm", "usl_mm", "measured_mm", "s_um", "n_repeats",
              "process_mean_mm", "process_sd_um"}


@dataclass
class ToleranceSpec:
    """One ``[[decision.tolerances]]`` entry (n: its 1-based number)."""

    n: int
    ident: dict[str, str]
    label: str
    nominal_mm: float | None = None
    tol_mm: float | None = None
    lsl_mm: float | None = None
    usl_mm: float | None = None
    measured_mm: float | None = None
    s_um: float | None = None        #: standard deviation of n repeated measurements (type A)
    n_repeats: float | None = None   #: the number of repeated measurements whose mean is the value
    process_mean_mm: float | None = None   #: a normal prior of the production process (JCGM 106:2012, 9.5)
    process_sd_um: float | None = None
    #: limits that are cells of the kind's own sheets ({"lsl_mm": formula text}), not inputs here
    limit_cells: dict[str, str] = field(default_factory=dict)
    #: the nominal value the task gives (None: the limits only)
    nominal_given: float | None = None

    @property
    def type_a(self) -> bool:
        return self.s_um is not None

    def tolerance(self, nominal_default: float) -> cf.Tolerance:
        if self.tol_mm is not None:
            nominal = self.nominal_mm if self.nominal_mm is not None else nominal_default
            return cf.Tolerance.symmetric(nominal, self.tol_mm)
        return cf.Tolerance(self.lsl_mm, self.usl_mm)

    @property
    def name_prefix(self) -> str:
        return f"tol{self.n}"


@dataclass
class DecisionSpec:
    rule: cf.DecisionRule
    k: float | None
    k_from_dof: bool = False
    tolerances: list[ToleranceSpec] = field(default_factory=list)


def tolerance_where(n: int, key: str | None = None) -> str:
    return f"{TOL_SECTION} #{n}" + (f" key '{key}'" if key else "")


#: the smallest standard deviation (s_um, process_sd_um) taken: below it u^4 of the
#: Welch-Satterthwaite formula underflows
MIN_SD_UM = 1e-6


def _num(path: Path, tbl: dict, key: str, where: str) -> float | None:
    """A finite number; a length (``_mm``) or a standard deviation (``_um``) within the plausible
    range of a coordinate measuring machine (xlfuncs.limits: +-100 m), whose arithmetic keeps a
    nanometre: beyond it the rounded statement and the risks overflow."""
    if key not in tbl:
        return None
    v = tbl[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise InputError(f"must be a finite number, got {v!r}", file=path, where=where)
    v = float(v)
    scale = 1e3 if key.endswith("_um") else 1.0 if key.endswith("_mm") else None
    if scale is not None and abs(v) > MAX_COORDINATE_MM * scale:
        unit = "µm" if scale > 1 else "mm"
        raise InputError(f"{v:g} {unit} is outside the plausible range of a CMM measurement "
                         f"(+-{MAX_COORDINATE_MM * scale:g} {unit}); is the unit {unit}?", file=path, where=where)
    if key.endswith("_um") and 0 < abs(v) < MIN_SD_UM:
        raise InputError(f"{v:g} µm is below {MIN_SD_UM:g} µm (a picometre): no CMM measurement repeats that "
                         "well; is the unit µm?", file=path, where=where)
    return v


def read_spec(path: Path, doc: dict, keys: ToleranceKeys) -> DecisionSpec | None:
    """The task's ``[decision]`` table, validated (None when the task has none); ``keys``: how the
    kind's ``[[decision.tolerances]]`` name its results (its ``TOLERANCE_KEYS``).  Every problem is
    an :class:`InputError` naming the key.  A kind whose results carry their own tolerances is
    decided without the table (:func:`default_spec`, after its results are known)."""
    tbl = doc.get(SECTION)
    if tbl is None:
        return None
    if not isinstance(tbl, dict):
        raise InputError("must be a table", file=path, where=f"[{SECTION}]")
    check_keys(path, tbl, SECTION, RULE_KEYS)
    rule_kind = tbl.get("rule", "iso14253")
    if not isinstance(rule_kind, str) or rule_kind not in cf.RULES:
        raise InputError(f"must be one of {', '.join(cf.RULES)}, got {rule_kind!r}", file=path,
                         where=f"[{SECTION}] rule")
    r = _num(path, tbl, "r", f"[{SECTION}] r")
    pfa = _num(path, tbl, "max_pfa", f"[{SECTION}] max_pfa")
    k = _num(path, tbl, "k", f"[{SECTION}] k")
    if r is not None and rule_kind not in ("guarded_acceptance", "guarded_rejection"):
        raise InputError(f"r (guard band w = r·U) applies to the guarded rules only, not to rule {rule_kind!r}",
                         file=path, where=f"[{SECTION}] r")
    if pfa is not None and rule_kind != "specific_risk":
        raise InputError(f"max_pfa applies to rule 'specific_risk' only, not to {rule_kind!r}",
                         file=path, where=f"[{SECTION}] max_pfa")
    if k is not None and not keys.k_from_decision:
        raise InputError("k is for tasks whose results give u only (U = k·u); this task's results give U "
                         "with their own coverage factor", file=path, where=f"[{SECTION}] k")
    if k is not None and not (0 < k <= 10):
        raise InputError(f"must be a coverage factor in (0, 10], got {k!r}", file=path, where=f"[{SECTION}] k")
    if r is not None and r > 10:     # like k: r = 1e300 accepted (guarded_rejection) any value at all
        raise InputError(f"must be a guard-band factor in [0, 10] (w = r·U), got {r!r}", file=path,
                         where=f"[{SECTION}] r")
    try:
        rule = cf.DecisionRule(rule_kind, 1.0 if r is None else r, 0.05 if pfa is None else pfa)
    except ModelError as e:
        key = "r" if "r =" in str(e) else "max_pfa"
        raise InputError(str(e), file=path, where=f"[{SECTION}] {key}") from None
    kfd = tbl.get("k_from_dof", False)
    if not isinstance(kfd, bool):
        raise InputError(f"must be true or false, got {kfd!r}", file=path, where=f"[{SECTION}] k_from_dof")
    spec = DecisionSpec(rule, (2.0 if k is None else k) if keys.k_from_decision else None, kfd)
    if keys.own:
        if "tolerances" in tbl:
            raise InputError("this task's tolerances are the lsl/usl/nominal/tolerance_mm of its "
                             "[[characteristics]]: leave [[decision.tolerances]] out", file=path,
                             where=f"[{SECTION}] tolerances")
        if kfd:
            raise InputError("k_from_dof needs type A repeatabilities, which this task does not take",
                             file=path, where=f"[{SECTION}] k_from_dof")
        return spec         # the tolerances: own_tolerances() of the records
    raw = tbl.get("tolerances")
    if not isinstance(raw, list) or not raw:
        raise InputError("no tolerances: add [[decision.tolerances]] tables (the characteristic and its "
                         "limits lsl_mm/usl_mm, or tol_mm around nominal_mm)", file=path,
                         where=f"[{SECTION}] tolerances")
    ident_keys = keys.keys
    seen: dict[str, int] = {}
    for n, entry in enumerate(raw, start=1):
        if not isinstance(entry, dict):
            raise InputError("must be a table", file=path, where=tolerance_where(n))
        check_keys(path, entry, f"{SECTION}.tolerances #{n}", set(ident_keys) | LIMIT_KEYS)
        ident = {}
        for key in ident_keys:
            v = entry.get(key)
            if not isinstance(v, str) or not v:
                raise InputError(f"missing: the {' and '.join(ident_keys)} of the characteristic "
                                 f"({keys.help})", file=path, where=tolerance_where(n, key))
            ident[key] = v
        label = keys.label(ident)
        if label in seen:
            raise InputError(f"{label!r} has a tolerance already (entry #{seen[label]})", file=path,
                             where=tolerance_where(n, ident_keys[0]))
        seen[label] = n
        t = ToleranceSpec(n, ident, label, **{k_: _num(path, entry, k_, tolerance_where(n, k_)) for k_ in LIMIT_KEYS})
        if t.tol_mm is not None and (t.lsl_mm is not None or t.usl_mm is not None):
            raise InputError("give either tol_mm (around nominal_mm) or lsl_mm/usl_mm, not both", file=path,
                             where=tolerance_where(n, "tol_mm"))
        if t.tol_mm is None and t.lsl_mm is None and t.usl_mm is None:
            raise InputError("no limits: give lsl_mm and/or usl_mm, or tol_mm (nominal ± tol_mm)", file=path,
                             where=tolerance_where(n))
        if (t.s_um is None) != (t.n_repeats is None):
            raise InputError("a type A repeatability needs both s_um (standard deviation of the repeated "
                             "measurements, µm) and n_repeats (their number)", file=path,
                             where=tolerance_where(n, "n_repeats" if t.n_repeats is None else "s_um"))
        if t.s_um is not None and not t.s_um > 0:
            raise InputError(f"must be positive, got {t.s_um!r}", file=path, where=tolerance_where(n, "s_um"))
        if t.n_repeats is not None and not (t.n_repeats == int(t.n_repeats) and 2 <= t.n_repeats <= 1e6):
            raise InputError(f"must be a whole number of repeated measurements >= 2, got {t.n_repeats!r}",
                             file=path, where=tolerance_where(n, "n_repeats"))
        if (t.process_mean_mm is None) != (t.process_sd_um is None):
            raise InputError("a process prior needs both process_mean_mm and process_sd_um (the mean and the "
                             "standard deviation of the characteristic over the production process)", file=path,
                             where=tolerance_where(n, "process_sd_um" if t.process_sd_um is None else "process_mean_mm"))
        if t.process_sd_um is not None and not t.process_sd_um > 0:
            raise InputError(f"must be positive, got {t.process_sd_um!r}", file=path,
                             where=tolerance_where(n, "process_sd_um"))
        if t.nominal_mm is not None and t.tol_mm is None:
            raise InputError("nominal_mm is the centre of tol_mm; with lsl_mm/usl_mm leave it out", file=path,
                             where=tolerance_where(n, "nominal_mm"))
        try:
            t.tolerance(0.0 if t.nominal_mm is None else t.nominal_mm)
        except ModelError as e:
            key = "tol_mm" if "tol_mm" in str(e) else ("lsl_mm" if t.lsl_mm is not None else "usl_mm")
            raise InputError(str(e), file=path, where=tolerance_where(n, key)) from None
        spec.tolerances.append(t)
    return spec


def default_spec(keys: ToleranceKeys, quantities: list[Quantity]) -> DecisionSpec | None:
    """A task without ``[decision]`` whose results carry their own tolerances (a drawing's
    characteristics) is still decided, by the default rule: ISO 14253-1 with k = 2
    (docs/conformity.md); None when it has none."""
    if not keys.own or not any(q.has_tolerance or q.decided_as or q.not_decided for q in quantities):
        return None
    return DecisionSpec(cf.DecisionRule("iso14253"), 2.0 if keys.k_from_decision else None)


def own_tolerances(quantities: list[Quantity]) -> tuple[list[ToleranceSpec], list[dict]]:
    """The tolerances that the records carry themselves (a drawing's characteristics: lsl, usl,
    the cells they are typed in), in their order, and the records with a tolerance that is not
    decided (name, reason: an angle)."""
    out: list[ToleranceSpec] = []
    skipped: list[dict] = []
    for q in quantities:
        if q.not_decided:
            skipped.append({"characteristic": q.label, "reason": q.not_decided})
        elif q.has_tolerance:
            out.append(ToleranceSpec(len(out) + 1, dict(q.ident), q.label, lsl_mm=q.lsl, usl_mm=q.usl,
                                     limit_cells=dict(q.cells.limits) if q.cells is not None else {},
                                     nominal_given=q.nominal))
    return out, skipped


def decide_all(path: Path, keys: ToleranceKeys, spec: DecisionSpec, quantities: list[Quantity]
               ) -> tuple[list[dict], list[dict]]:
    """The decisions (JSON entries) of every tolerance, in the order of the task file, and the
    tolerances that are not decided (for a kind with its own tolerances, :func:`own_tolerances`,
    which fill ``spec.tolerances``)."""
    skipped: list[dict] = []
    if keys.own:
        spec.tolerances, skipped = own_tolerances(quantities)
    by_label = {q.label: q for q in quantities}
    out = []
    for t in spec.tolerances:
        q = by_label.get(t.label)
        if q is None or not q.decidable:
            have = [lab for lab, x in by_label.items() if x.decidable]
            listed = ", ".join(have[:8]) + (" ..." if len(have) > 8 else "")
            raise InputError(f"no characteristic {t.label!r} in the results (there are: {listed})" + keys.hint,
                             file=path, where=tolerance_where(t.n, keys.keys[0] if keys.keys else None))
        where = f"[[characteristics]] {t.label}" if keys.own else tolerance_where(t.n)
        try:
            tol = t.tolerance(q.value)
        except ModelError as e:          # lsl >= usl on a characteristic (the others: read_spec)
            raise InputError(str(e), file=path, where=where) from None
        value = q.value if t.measured_mm is None else t.measured_mm
        unc = combined(q, t, spec)
        try:
            d = cf.decide(value, unc["u_um"], tol, spec.rule, unc["k"])
        except ModelError as e:
            raise InputError(str(e), file=path, where=where) from None
        nu = math.inf if unc["nu_eff"] is None else unc["nu_eff"]
        entry = {"characteristic": t.label, **{k_: v for k_, v in t.ident.items()},
                 **({"quantity": q.quantity} if keys.own else {}),
                 "value_source": "measured_mm" if t.measured_mm is not None else "task", **d.as_dict(),
                 **{k_: v for k_, v in unc.items() if k_ not in ("u_um", "k")},
                 "coverage_probability": dof.coverage_probability(d.k, nu),
                 "nominal_mm": nominal_of(t, q),
                 "value_source_text": value_source_text(t, q),
                 "statement": statement(q.symbol, value, "mm", d.U_um, "µm", d.k, nu=nu)}
        if t.process_sd_um is not None:
            g = gr.global_risks_normal(t.process_mean_mm, t.process_sd_um, d.u_um, tol, d.acceptance_mm)
            entry.update(process_mean_mm=t.process_mean_mm, process_sd_um=t.process_sd_um,
                         process_nonconforming=g.nonconforming, global_consumer_risk=g.consumer,
                         global_producer_risk=g.producer)
        out.append(entry)
    return out, skipped


def nominal_of(t: ToleranceSpec, q: Quantity) -> float | None:
    """The nominal value of a tolerance: ``nominal_mm`` (or the task's value, the centre of
    ``tol_mm`` without it), a drawing's nominal; None when the task gives limits only."""
    if t.tol_mm is not None:
        return t.nominal_mm if t.nominal_mm is not None else q.value
    return t.nominal_given


def value_source_text(t: ToleranceSpec, q: Quantity) -> str:
    """Where the decided value comes from, in words: typed (``measured_mm``, with its repeated
    measurements) or the task's (the record's source)."""
    if t.measured_mm is None:
        return q.value_source
    text = f"typed measured value ({tolerance_where(t.n, 'measured_mm')})"
    if t.type_a:
        text += ", the mean of the repeated measurements (s_um, n_repeats)"
    return text + f"; not the task's own value (on Results), which is {q.value_source}"


def combined(q: Quantity, t: ToleranceSpec, spec: DecisionSpec) -> dict:
    """u, ν_eff and k of one characteristic: the task's u (type B, ν = ∞) and, when the tolerance
    gives a repeatability s_um of n repeated measurements, u_A = s/√n with ν_A = n - 1 (GUM 4.2),
    combined in quadrature; ν_eff by Welch–Satterthwaite (GUM G.4.1); k = t_95.45(⌊ν_eff⌋) when
    ``[decision] k_from_dof`` (GUM G.6.4), else the task's k."""
    out = {"u_task_um": q.u, "distribution": "normal", "u_A_um": None, "nu_A": None, "nu_eff": None}
    u = q.u
    k = q.k if q.own_U or spec.k is None else spec.k
    if t.type_a:
        u_a = t.s_um / math.sqrt(t.n_repeats)
        nu_a = t.n_repeats - 1
        u = math.hypot(q.u, u_a)
        nu = dof.nu_eff([q.u, u_a], [math.inf, nu_a])
        out.update(u_A_um=u_a, nu_A=nu_a, nu_eff=nu)
        if spec.k_from_dof:
            k = dof.coverage_factor(nu)
            out["distribution"] = "t"
    out.update(u_um=u, k=k)
    return out


def rule_json(spec: DecisionSpec) -> dict:
    r = spec.rule
    out = {"rule": r.kind, "text": r.text}
    if r.kind in ("guarded_acceptance", "guarded_rejection"):
        out["r"] = r.r
    if r.kind == "specific_risk":
        out["max_pfa"] = r.max_pfa
    if spec.k is not None:
        out["k"] = spec.k
    if spec.k_from_dof:
        out["k_from_dof"] = True
    return out
