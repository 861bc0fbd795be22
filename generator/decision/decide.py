"""The conformity decisions of a task as data: the ``[decision]`` table and its tolerances read
and validated, and the decisions of the results JSON.

Every task kind has characteristics with a value and an uncertainty in its ``Results`` sheet:
budget characteristics (``value_mm``, ``u_um``, ``U_um``), point-cloud distances (``d_mm``,
``u_um``, ``U_um``) and feature parameters in mm (``value``, ``u``; U = k·u with the
``[decision] k``).  A ``[[decision.tolerances]]`` entry names one of them and gives its
specification limits; the decision rule of ``[decision]`` turns value, U and limits into a
decision (:mod:`xlfuncs.conformity`, JCGM 106:2012 and ISO 14253-1:2017).  The ``Decision``
sheet that computes the same with live formulas is :mod:`generator.decision.sheet`.
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
from ..taskfile import check_keys

SECTION = "decision"
TOL_SECTION = "[[decision.tolerances]]"
RULE_KEYS = {"rule", "r", "max_pfa", "k", "k_from_dof", "tolerances"}
#: the key(s) that name the characteristic of a tolerance, per task kind
IDENT_KEYS = {"budget": ("characteristic",), "pointcloud": ("from", "to"), "feature": ("parameter",),
              "characteristic": ("characteristic",)}
#: kinds whose results have u but no U: U = k·u with the ``[decision] k`` (default 2)
K_KINDS = ("feature", "characteristic")
#: kinds whose tolerances are fields of their own characteristics, not ``[[decision.tolerances]]``
OWN_TOLERANCES = ("characteristic",)
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


def read_spec(path: Path, doc: dict, kind: str) -> DecisionSpec | None:
    """The task's ``[decision]`` table, validated (None when the task has none).  Every problem is
    an :class:`InputError` naming the key."""
    tbl = doc.get(SECTION)
    if tbl is None and kind in OWN_TOLERANCES and _has_own_tolerances(doc):
        tbl = {}            # tolerances on the characteristics, no [decision]: the default rule
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
    if k is not None and kind not in K_KINDS:
        raise InputError("k is for feature tasks and characteristic tasks (whose results have no U); a "
                         f"{kind} task's U uses its own coverage factor", file=path, where=f"[{SECTION}] k")
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
    spec = DecisionSpec(rule, (2.0 if k is None else k) if kind in K_KINDS else None, kfd)
    if kind in OWN_TOLERANCES:
        if "tolerances" in tbl:
            raise InputError(f"a {kind} task's tolerances are the lsl/usl/nominal/tolerance_mm of its "
                             "[[characteristics]]: leave [[decision.tolerances]] out", file=path,
                             where=f"[{SECTION}] tolerances")
        if kfd:
            raise InputError(f"k_from_dof needs type A repeatabilities, which a {kind} task does not take",
                             file=path, where=f"[{SECTION}] k_from_dof")
        return spec         # the tolerances: characteristic_tolerances() from the results
    raw = tbl.get("tolerances")
    if not isinstance(raw, list) or not raw:
        raise InputError("no tolerances: add [[decision.tolerances]] tables (the characteristic and its "
                         "limits lsl_mm/usl_mm, or tol_mm around nominal_mm)", file=path,
                         where=f"[{SECTION}] tolerances")
    ident_keys = IDENT_KEYS[kind]
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
                                 f"({_IDENT_HELP[kind]})", file=path, where=tolerance_where(n, key))
            ident[key] = v
        label = "→".join(ident[k_] for k_ in ident_keys) if kind == "pointcloud" else ident[ident_keys[0]]
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


def _has_own_tolerances(doc: dict) -> bool:
    chars = doc.get("characteristics")
    return isinstance(chars, list) and any(isinstance(c, dict) and any(
        k_ in c for k_ in ("lsl", "usl", "tolerance_mm")) for c in chars)


_IDENT_HELP = {"budget": "characteristic = the name of a [[characteristics]] entry",
               "pointcloud": "from and to = the point ids of a distance",
               "feature": "parameter = a length parameter of the fit, e.g. \"r0_mm\""}


# -- the characteristics of each kind's results -----------------------------------------------

@dataclass(frozen=True)
class Row:
    """A characteristic as the Results sheet holds it."""

    label: str
    index: int               #: 0-based row of the Results sheet below its header
    value_mm: float
    u_um: float
    U_um: float | None       #: None: U = k·u computed on the Decision sheet (feature)
    value_col: str           #: Results column names
    u_col: str
    U_col: str | None
    u_scale: float           #: µm per unit of the u column (1, or 1000 for a feature's mm)
    k: float
    sheet: str = "Results"   #: the sheet of the value and u columns (header in row 1, same rows)


def rows_of(kind: str, results: dict, spec: DecisionSpec) -> dict[str, Row]:
    out: dict[str, Row] = {}
    if kind == "budget":
        k = float(results["mpe"]["k"])
        for i, c in enumerate(results["characteristics"]):
            out[c["name"]] = Row(c["name"], i, c["value_mm"], c["u_um"], c["U_um"], "value_mm", "u_um", "U_um", 1.0, k)
    elif kind == "pointcloud":
        k = float(results.get("K", 2.0))
        for i, d in enumerate(results["distances"]):
            label = f"{d['from']}→{d['to']}"
            out.setdefault(label, Row(label, i, d["d_mm"], d["u_um"], d["U_um"], "d_mm", "u_um", "U_um", 1.0, k))
    elif kind == "feature":
        fe = results["feature"]
        for i, n in enumerate(fe["parameter_names"]):
            if n.endswith("_mm"):
                out[n] = Row(n, i, fe["parameters"][n], fe["u"][n] * 1000.0, None, "value", "u", None, 1000.0,
                             float(spec.k))
    elif kind == "characteristic":
        for i, c in enumerate(results["characteristics"]):
            if c["unit"] != "mm":
                continue          # angles (deg): not decided (docs/conformity.md)
            out[c["name"]] = Row(c["name"], i, c["value"], c["u"], None, "value", "u", None, 1.0, float(spec.k))
            if c["margin_mm"] is not None and c["material_condition"] in BONUS_CONDITIONS:
                label = margin_label(c["name"])
                out[label] = Row(label, i, c["margin_mm"], c["u_margin_um"], None, "margin_mm", "u_margin_um",
                                 None, 1.0, float(spec.k), sheet="Characteristics")
    return out


# -- the characteristic kind: tolerances from the characteristics' own fields -------------------------

#: material conditions with a bonus tolerance: decided on the margin (zone - value >= 0)
BONUS_CONDITIONS = ("MMC", "LMC")
#: characteristic types with a two-sided tolerance interval (lsl/usl or nominal ± tolerance_mm)
TWO_SIDED_TYPES = ("diameter", "width", "distance", "cone_angle", "angle")


def margin_label(name: str) -> str:
    """The decided quantity of a position at MMC/LMC: its margin (Characteristics, 'margin_mm')."""
    return f"{name} margin"


def characteristic_tolerances(results: dict) -> tuple[list[ToleranceSpec], list[dict]]:
    """The tolerances of a ``characteristic`` task, from the fields of its characteristics, and
    the characteristics with a tolerance that are not decided (name, reason).

    * size, distance (two-sided): ``lsl``/``usl`` (one of them: a one-sided interval), or
      ``nominal`` ± ``tolerance_mm``;
    * form, orientation, position RFS (a zone whose value is >= 0): one-sided, value <= USL =
      ``tolerance_mm`` (ISO 1101: the feature lies in a zone of that width);
    * position at MMC/LMC: the margin m = tolerance + bonus - value >= 0, a one-sided lower
      limit 0 on m, whose u (``u_margin_um``) includes the bonus's uncertainty through the
      measured size and its correlation with the position (both from one V_X);
    * angles (deg): not decided yet (the decision's fields are mm and µm).

    ``limit_cells``: the limits as formulas of the 'Characteristics' cells (column names of its
    header), so that a tolerance typed there changes the decision."""
    out: list[ToleranceSpec] = []
    skipped: list[dict] = []
    for c in results["characteristics"]:
        name, typ = c["name"], c["type"]
        lsl, usl, tol, nominal = c["lsl"], c["usl"], c["tolerance_mm"], c["nominal"]
        if lsl is None and usl is None and tol is None:
            continue
        n = len(out) + 1
        ident = {"characteristic": name}
        if c["unit"] != "mm":
            skipped.append({"characteristic": name, "reason": f"an angle tolerance ({c['unit']}) is not decided "
                            "yet: the decision works in mm and µm"})
            continue
        if typ in TWO_SIDED_TYPES:
            if lsl is not None or usl is not None:
                cells = {k_: f"{{{k_[:3]}}}" for k_, v in (("lsl_mm", lsl), ("usl_mm", usl)) if v is not None}
                out.append(ToleranceSpec(n, ident, name, lsl_mm=lsl, usl_mm=usl, limit_cells=cells))
            elif nominal is not None:
                out.append(ToleranceSpec(n, ident, name, lsl_mm=nominal - tol, usl_mm=nominal + tol,
                                         limit_cells={"lsl_mm": "{nominal}-{tolerance_mm}",
                                                      "usl_mm": "{nominal}+{tolerance_mm}"}))
            else:
                skipped.append({"characteristic": name, "reason": "tolerance_mm of a size or distance needs "
                                "its nominal (nominal ± tolerance_mm), or give lsl/usl"})
            continue
        if tol is None:
            skipped.append({"characteristic": name, "reason": f"a {typ} takes tolerance_mm (a zone width), "
                            "not lsl/usl"})
            continue
        if typ == "position" and c["material_condition"] in BONUS_CONDITIONS:
            out.append(ToleranceSpec(n, {"characteristic": margin_label(name)}, margin_label(name), lsl_mm=0.0,
                                     limit_cells={"lsl_mm": "0"}))
        else:
            out.append(ToleranceSpec(n, ident, name, usl_mm=tol, limit_cells={"usl_mm": "{tolerance_mm}"}))
    return out, skipped


def decide_all(path: Path, kind: str, spec: DecisionSpec, results: dict) -> list[dict]:
    """The decisions (JSON entries) of every tolerance, in the order of the task file (for the
    characteristic kind: of every characteristic with a tolerance, :func:`characteristic_tolerances`,
    which fills ``spec.tolerances``)."""
    if kind in OWN_TOLERANCES:
        spec.tolerances, skipped = characteristic_tolerances(results)
        if skipped:
            results["not_decided"] = skipped
    rows = rows_of(kind, results, spec)
    out = []
    for t in spec.tolerances:
        row = rows.get(t.label)
        if row is None:
            key = IDENT_KEYS[kind][0]
            have = ", ".join(list(rows)[:8]) + (" ..." if len(rows) > 8 else "")
            raise InputError(f"no characteristic {t.label!r} in the results (there are: {have})"
                             + (" ; only length parameters (_mm) take a tolerance" if kind == "feature" else ""),
                             file=path, where=tolerance_where(t.n, key))
        try:
            tol = t.tolerance(row.value_mm)
        except ModelError as e:          # lsl >= usl on a characteristic (the others: read_spec)
            raise InputError(str(e), file=path, where=f"[[characteristics]] {t.label}") from None
        value = row.value_mm if t.measured_mm is None else t.measured_mm
        unc = combined(row, t, spec)
        try:
            d = cf.decide(value, unc["u_um"], tol, spec.rule, unc["k"])
        except ModelError as e:
            where = (f"[[characteristics]] {t.ident['characteristic']}" if kind in OWN_TOLERANCES
                     else tolerance_where(t.n))
            raise InputError(str(e), file=path, where=where) from None
        entry = {"characteristic": t.label, **{k_: v for k_, v in t.ident.items()},
                 **({"quantity": "margin_mm" if row.value_col == "margin_mm" else "value"}
                    if kind in OWN_TOLERANCES else {}),
                 "value_source": "measured_mm" if t.measured_mm is not None else "task", **d.as_dict(),
                 **{k_: v for k_, v in unc.items() if k_ not in ("u_um", "k")},
                 "statement": statement(symbol(kind, t.label), value, "mm", d.U_um, "µm", d.k)}
        if t.process_sd_um is not None:
            g = gr.global_risks_normal(t.process_mean_mm, t.process_sd_um, d.u_um, tol, d.acceptance_mm)
            entry.update(process_mean_mm=t.process_mean_mm, process_sd_um=t.process_sd_um,
                         process_nonconforming=g.nonconforming, global_consumer_risk=g.consumer,
                         global_producer_risk=g.producer)
        out.append(entry)
    return out


def combined(row: Row, t: ToleranceSpec, spec: DecisionSpec) -> dict:
    """u, ν_eff and k of one characteristic: the task's u (type B, ν = ∞) and, when the tolerance
    gives a repeatability s_um of n repeated measurements, u_A = s/√n with ν_A = n - 1 (GUM 4.2),
    combined in quadrature; ν_eff by Welch–Satterthwaite (GUM G.4.1); k = t_95.45(⌊ν_eff⌋) when
    ``[decision] k_from_dof`` (GUM G.6.4), else the task's k."""
    out = {"u_task_um": row.u_um, "distribution": "normal", "u_A_um": None, "nu_A": None, "nu_eff": None}
    u, k = row.u_um, row.k
    if t.type_a:
        u_a = t.s_um / math.sqrt(t.n_repeats)
        nu_a = t.n_repeats - 1
        u = math.hypot(row.u_um, u_a)
        nu = dof.nu_eff([row.u_um, u_a], [math.inf, nu_a])
        out.update(u_A_um=u_a, nu_A=nu_a, nu_eff=nu)
        if spec.k_from_dof:
            k = dof.coverage_factor(nu)
            out["distribution"] = "t"
    out.update(u_um=u, k=k)
    return out


def symbol(kind: str, label: str) -> str:
    """The quantity's symbol in a result statement: the characteristic's name, or d(FROM→TO)."""
    return f"d({label})" if kind == "pointcloud" else label


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
