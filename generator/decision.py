"""Conformity decisions of a task: the ``[decision]`` table, its tolerances, the decisions in the
results JSON and the ``Decision`` sheet (live formulas) of the workbook.

Every task kind has characteristics with a value and an uncertainty in its ``Results`` sheet:
budget characteristics (``value_mm``, ``u_um``, ``U_um``), point-cloud distances (``d_mm``,
``u_um``, ``U_um``) and feature parameters in mm (``value``, ``u``; U = k·u with the
``[decision] k``).  A ``[[decision.tolerances]]`` entry names one of them and gives its
specification limits; the decision rule of ``[decision]`` turns value, U and limits into a
decision (:mod:`xlfuncs.conformity`, JCGM 106:2012 and ISO 14253-1:2017).

The sheet computes everything from the Results cells and its own inputs (limits, measured
values, r, max_pfa, k) with formulas all three engines accept (``_xlfn.NORM.S.DIST``,
``_xlfn.NORM.S.INV``, measured in ``docs/engines.md``).
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from openpyxl.chart import Reference

from xlfuncs import conformity as cf
from xlfuncs import dof
from xlfuncs.errors import ModelError
from xlfuncs.statement import decimals_for, statement

from .errors import InputError
from .taskfile import check_keys
from .workbook.book import HEADER_FONT, TITLE_FONT, Book, ChartSeries, FMT_MM, FMT_UM
from .workbook.xlref import cell, col, quote_sheet

SHEET = "Decision"
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
LIMIT_KEYS = {"nominal_mm", "tol_mm", "lsl_mm", "usl_mm", "measured_mm", "s_um", "n_repeats"}
FMT_P = "0.000000"
HEADER_ROW = 7
FIRST_ROW = HEADER_ROW + 1     #: the first characteristic's row
#: columns of the decision table (first row of the table: headers with units)
COLUMNS = ["item", "characteristic", "value_mm", "u_task_um", "s_um", "n_repeats", "u_A_um", "nu_A", "u_um", "nu_eff",
           "k", "U_um", "lsl_mm", "usl_mm", "w_um", "A_L_mm", "A_U_mm", "R_L_mm", "R_U_mm", "p_c", "outcome",
           "zone"]


def column(name: str) -> int:
    """1-based column of the Decision table (``COLUMNS``)."""
    return COLUMNS.index(name) + 1
#: chart data: deviations from the reference (tolerance midpoint or the one limit), µm
CHART_COLUMNS = ["dev_um", "dev_plus_U_um", "dev_minus_U_um", "lsl_dev_um", "usl_dev_um",
                 "A_L_dev_um", "A_U_dev_um"]


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


def _where(n: int, key: str | None = None) -> str:
    return f"{TOL_SECTION} #{n}" + (f" key '{key}'" if key else "")


def _num(path: Path, tbl: dict, key: str, where: str) -> float | None:
    if key not in tbl:
        return None
    v = tbl[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise InputError(f"must be a finite number, got {v!r}", file=path, where=where)
    return float(v)


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
            raise InputError("must be a table", file=path, where=_where(n))
        check_keys(path, entry, f"{SECTION}.tolerances #{n}", set(ident_keys) | LIMIT_KEYS)
        ident = {}
        for key in ident_keys:
            v = entry.get(key)
            if not isinstance(v, str) or not v:
                raise InputError(f"missing: the {' and '.join(ident_keys)} of the characteristic "
                                 f"({_IDENT_HELP[kind]})", file=path, where=_where(n, key))
            ident[key] = v
        label = "→".join(ident[k_] for k_ in ident_keys) if kind == "pointcloud" else ident[ident_keys[0]]
        if label in seen:
            raise InputError(f"{label!r} has a tolerance already (entry #{seen[label]})", file=path,
                             where=_where(n, ident_keys[0]))
        seen[label] = n
        t = ToleranceSpec(n, ident, label, **{k_: _num(path, entry, k_, _where(n, k_)) for k_ in LIMIT_KEYS})
        if t.tol_mm is not None and (t.lsl_mm is not None or t.usl_mm is not None):
            raise InputError("give either tol_mm (around nominal_mm) or lsl_mm/usl_mm, not both", file=path,
                             where=_where(n, "tol_mm"))
        if t.tol_mm is None and t.lsl_mm is None and t.usl_mm is None:
            raise InputError("no limits: give lsl_mm and/or usl_mm, or tol_mm (nominal ± tol_mm)", file=path,
                             where=_where(n))
        if (t.s_um is None) != (t.n_repeats is None):
            raise InputError("a type A repeatability needs both s_um (standard deviation of the repeated "
                             "measurements, µm) and n_repeats (their number)", file=path,
                             where=_where(n, "n_repeats" if t.n_repeats is None else "s_um"))
        if t.s_um is not None and not t.s_um > 0:
            raise InputError(f"must be positive, got {t.s_um!r}", file=path, where=_where(n, "s_um"))
        if t.n_repeats is not None and not (t.n_repeats == int(t.n_repeats) and 2 <= t.n_repeats <= 1e6):
            raise InputError(f"must be a whole number of repeated measurements >= 2, got {t.n_repeats!r}",
                             file=path, where=_where(n, "n_repeats"))
        if t.nominal_mm is not None and t.tol_mm is None:
            raise InputError("nominal_mm is the centre of tol_mm; with lsl_mm/usl_mm leave it out", file=path,
                             where=_where(n, "nominal_mm"))
        try:
            t.tolerance(0.0 if t.nominal_mm is None else t.nominal_mm)
        except ModelError as e:
            key = "tol_mm" if "tol_mm" in str(e) else ("lsl_mm" if t.lsl_mm is not None else "usl_mm")
            raise InputError(str(e), file=path, where=_where(n, key)) from None
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
                             file=path, where=_where(t.n, key))
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
                     else _where(t.n))
            raise InputError(str(e), file=path, where=where) from None
        entry = {"characteristic": t.label, **{k_: v for k_, v in t.ident.items()},
                 **({"quantity": "margin_mm" if row.value_col == "margin_mm" else "value"}
                    if kind in OWN_TOLERANCES else {}),
                 "value_source": "measured_mm" if t.measured_mm is not None else "task", **d.as_dict(),
                 **{k_: v for k_, v in unc.items() if k_ not in ("u_um", "k")},
                 "statement": statement(symbol(kind, t.label), value, "mm", d.U_um, "µm", d.k)}
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


# -- the Decision sheet -----------------------------------------------------------------------------

def _results_cols(book: Book, sheet: str = "Results") -> dict[str, int]:
    """Column (1-based) of each header name in row 1 of ``sheet``."""
    ws = book.wb[sheet]
    return {str(c.value): c.column for c in ws[1] if c.value is not None}


def write_sheet(book: Book, kind: str, spec: DecisionSpec, results: dict, decisions: list[dict]
                ) -> dict[str, dict[str, Any]]:
    """The ``Decision`` sheet; returns the values to cache in its formula cells
    ({sheet: {coordinate: value}}, from the core's ``decisions``)."""
    rows = rows_of(kind, results, spec)
    sheet_cols = {name: _results_cols(book, name) for name in {row.sheet for row in rows.values()}}
    ws = book.sheet(SHEET)
    cache: dict[str, Any] = {}
    rule = spec.rule
    book.text(ws, 1, 1, "Conformity decisions", font=TITLE_FONT)
    intro = textwrap.wrap(f"Decision rule: {rule.text}. p_c = probability of conformance, normal PDF "
                          "(JCGM 106:2012, 7.3-7.4); A = acceptance limits, R = limits beyond which the value "
                          "does not conform; w = guard band (µm).", 150)
    for j, line in enumerate(intro[:HEADER_ROW - 3]):
        book.text(ws, 2 + j, 1, line)
    # rule parameters (named inputs)
    r0 = HEADER_ROW - 1
    book.text(ws, r0, 1, "rule", font=HEADER_FONT)
    book.text(ws, r0, 2, rule.kind)
    params = []
    if rule.kind in ("guarded_acceptance", "guarded_rejection"):
        params.append(("decision_r", "r", rule.r, 0.0, 10.0, "guard band factor: w = r·U (JCGM 106:2012, 8.3.2)"))
    if rule.kind == "specific_risk":
        params.append(("decision_max_pfa", "max_pfa", rule.max_pfa, 1e-9, 0.5,
                       "largest probability of false acceptance: accept when p_c >= 1 - max_pfa (JCGM 106:2012, 9.3)"))
    if spec.k is not None:
        params.append(("decision_k", "k", spec.k, 0.1, 10.0, "coverage factor: U = k·u"))
    for j, (name, label, value, lo, hi, note) in enumerate(params):
        book.text(ws, r0, 3 + 2 * j, label, font=HEADER_FONT)
        book.input(ws, r0, 4 + 2 * j, name, value, lo=lo, hi=hi, note=note)
    h = HEADER_ROW
    book.header(ws, h, 1, COLUMNS + CHART_COLUMNS, notes=[
        None, "the characteristic (Results row)", "measured value (input) or the task's value (from Results)",
        "the task's standard uncertainty (type B, ν = ∞)",
        "repeatability: standard deviation of the n repeated measurements whose mean is the value (input)",
        "number of repeated measurements (input)", "type A: u_A = s/√n (GUM 4.2.3)", "ν_A = n - 1 (GUM G.3.3)",
        "combined standard uncertainty u = √(u_task² + u_A²)",
        "effective degrees of freedom, Welch–Satterthwaite (GUM G.4.1, eq. (G.2b))",
        "coverage factor: t_95.45(⌊ν_eff⌋) with [decision] k_from_dof (GUM G.6.4), else the task's k",
        "expanded uncertainty U = k·u", "lower specification limit (input)",
        "upper specification limit (input)", "guard band; > 0: acceptance interval inside the tolerance",
        "lower acceptance limit A_L = T_L + w (JCGM 106:2012, 8.3)", "upper acceptance limit A_U = T_U - w",
        "below R_L: does not conform", "above R_U: does not conform",
        "probability of conformance p_c = Φ((T_U-y)/u) - Φ((T_L-y)/u) (JCGM 106:2012, eq. (12))",
        "the decision", "the zone of the measured value"] + [f"chart: {c} from the tolerance midpoint "
                                                              "(one-sided: from the limit)" for c in CHART_COLUMNS])
    c = {name: j + 1 for j, name in enumerate(COLUMNS + CHART_COLUMNS)}
    for i, (t, d) in enumerate(zip(spec.tolerances, decisions)):
        r = h + 1 + i
        row = rows[t.label]
        rr = row.index + 2
        results_sheet = quote_sheet(row.sheet)
        rcols = sheet_cols[row.sheet]
        fmt_mm = mm_format(d["U_um"])
        at = lambda name: cell(r, c[name], absolute=False)  # noqa: E731
        ws.cell(r, c["item"]).value = i + 1
        book.text(ws, r, c["characteristic"], t.label)
        if t.measured_mm is not None:
            book.input(ws, r, c["value_mm"], f"{t.name_prefix}_measured_mm", t.measured_mm, fmt=fmt_mm,
                       note="measured value (input)")
        else:
            book.formula(ws, r, c["value_mm"], f"={results_sheet}!{cell(rr, rcols[row.value_col])}", fmt=fmt_mm,
                         note="the task's value (Results); give [[decision.tolerances]] measured_mm for a measured one")
            cache[at("value_mm")] = d["value_mm"]
        u_ref = f"{results_sheet}!{cell(rr, rcols[row.u_col])}"
        book.formula(ws, r, c["u_task_um"], f"={u_ref}" if row.u_scale == 1 else f"={u_ref}*{row.u_scale:g}",
                     fmt=FMT_UM)
        cache[at("u_task_um")] = d["u_task_um"]
        # the task's own coverage factor: U/u of its Results (budget, pointcloud) or [decision] k
        k_task = (f"{results_sheet}!{cell(rr, rcols[row.U_col])}/{u_ref}" if row.U_col is not None
                  else "decision_k")
        if t.type_a:
            book.input(ws, r, c["s_um"], f"{t.name_prefix}_s_um", t.s_um, lo=0.0, fmt=FMT_UM,
                       note="standard deviation of the repeated measurements (µm)")
            book.input(ws, r, c["n_repeats"], f"{t.name_prefix}_n_repeats", t.n_repeats, lo=2.0, fmt="0",
                       note="number of repeated measurements")
            book.formula(ws, r, c["u_A_um"], f"={at('s_um')}/SQRT({at('n_repeats')})", fmt=FMT_UM)
            book.formula(ws, r, c["nu_A"], f"={at('n_repeats')}-1", fmt="0")
            book.formula(ws, r, c["u_um"], f"=SQRT({at('u_task_um')}^2+{at('u_A_um')}^2)", fmt=FMT_UM)
            book.formula(ws, r, c["nu_eff"], f"={at('u_um')}^4/({at('u_A_um')}^4/{at('nu_A')})", fmt="0.00")
            cache.update({at("u_A_um"): d["u_A_um"], at("nu_A"): d["nu_A"], at("nu_eff"): d["nu_eff"]})
            if spec.k_from_dof:
                book.formula(ws, r, c["k"], f"=_xlfn.T.INV.2T(1-{dof.P_K2},INT({at('nu_eff')}))", fmt="0.000",
                             note="t_95.45(ν) for ν = ⌊ν_eff⌋ (GUM G.6.4)")
            else:
                book.formula(ws, r, c["k"], f"={k_task}", fmt="0.000")
            book.formula(ws, r, c["U_um"], f"={at('k')}*{at('u_um')}", fmt=FMT_UM)
        else:
            for name in ("s_um", "n_repeats", "u_A_um", "nu_A"):
                book.text(ws, r, c[name], "—")
            book.text(ws, r, c["nu_eff"], "∞")
            book.formula(ws, r, c["u_um"], f"={at('u_task_um')}", fmt=FMT_UM)
            book.formula(ws, r, c["k"], f"={k_task}", fmt="0.000")
            if row.U_col is not None:
                book.formula(ws, r, c["U_um"], f"={results_sheet}!{cell(rr, rcols[row.U_col])}", fmt=FMT_UM)
            else:
                book.formula(ws, r, c["U_um"], f"={at('k')}*{at('u_um')}", fmt=FMT_UM)
        cache[at("u_um")] = d["u_um"]
        cache[at("k")] = d["k"]
        cache[at("U_um")] = d["U_um"]
        tol = d
        for key in ("lsl_mm", "usl_mm"):
            if tol[key] is None:
                book.text(ws, r, c[key], "—")
            elif key in t.limit_cells:      # the kind's own tolerance cell (Characteristics)
                ccols = sheet_cols.get("Characteristics") or _results_cols(book, "Characteristics")
                expr = t.limit_cells[key].format(**{name: f"{quote_sheet('Characteristics')}!{cell(rr, j)}"
                                                    for name, j in ccols.items() if name.isidentifier()})
                book.formula(ws, r, c[key], f"={expr}", fmt=fmt_mm,
                             note=("the tolerance typed on 'Characteristics'" if expr != "0" else
                                   "a margin (zone - value) conforms when >= 0"))
                cache[at(key)] = tol[key]
            else:
                book.input(ws, r, c[key], f"{t.name_prefix}_{key}", tol[key], fmt=fmt_mm,
                           note=("lower" if key == "lsl_mm" else "upper") + " specification limit (mm)")
        y, u, U = at("value_mm"), at("u_um"), at("U_um")
        lsl = at("lsl_mm") if tol["lsl_mm"] is not None else None
        usl = at("usl_mm") if tol["usl_mm"] is not None else None
        w = {"simple": "=0", "iso14253": f"={U}", "guarded_acceptance": f"=decision_r*{U}",
             "guarded_rejection": f"=-(decision_r*{U})",
             "specific_risk": f"=_xlfn.NORM.S.INV(1-decision_max_pfa)*{u}"}[rule.kind]
        book.formula(ws, r, c["w_um"], w, fmt=FMT_UM)
        cache[at("w_um")] = d["w_um"]
        wc = at("w_um")
        acc = [None, None]
        sides = ((lsl, "+", "A_L_mm", "R_L_mm"), (usl, "-", "A_U_mm", "R_U_mm"))
        for j, (lim, sign, a_name, r_name) in enumerate(sides):
            if lim is None:
                book.text(ws, r, c[a_name], "—")
                book.text(ws, r, c[r_name], "—")
                continue
            book.formula(ws, r, c[a_name], f"={lim}{sign}{wc}/1000", fmt=fmt_mm)
            cache[at(a_name)] = d["acceptance_limits_mm"][j]
            acc[j] = at(a_name)
            other = "-" if sign == "+" else "+"
            if rule.kind == "iso14253":
                book.formula(ws, r, c[r_name], f"={lim}{other}{U}/1000", fmt=fmt_mm)
                cache[at(r_name)] = (d["lsl_mm"] - d["U_um"] / 1000) if j == 0 else (d["usl_mm"] + d["U_um"] / 1000)
            else:
                book.formula(ws, r, c[r_name], f"={at(a_name)}", fmt=fmt_mm)
                cache[at(r_name)] = d["acceptance_limits_mm"][j]
        terms = []
        if usl is not None:
            terms.append(f"_xlfn.NORM.S.DIST(({usl}-{y})*1000/{u},TRUE)")
        if lsl is not None:
            terms.append(f"_xlfn.NORM.S.DIST(({lsl}-{y})*1000/{u},TRUE)")
        pc = terms[0] if usl is not None else f"1-{terms[0]}"
        if len(terms) == 2:
            pc = f"{terms[0]}-{terms[1]}"
        book.formula(ws, r, c["p_c"], "=" + pc, fmt=FMT_P,
                     note="JCGM 106:2012, 7.3 eq. (9)-(10) and 7.4 eq. (12); u in µm, limits in mm")
        cache[at("p_c")] = d["p_c"]
        inside_acc = _inside(y, acc[0], acc[1])
        rl = at("R_L_mm") if lsl is not None else None
        ru = at("R_U_mm") if usl is not None else None
        if rule.kind == "iso14253":
            outside_rej = _outside(y, rl, ru)
            outcome = (f'=IF({inside_acc},"{cf.CONFORMS}",IF({outside_rej},"{cf.DOES_NOT_CONFORM}",'
                       f'"{cf.UNDECIDED}"))')
            zone = (f'=IF({inside_acc},"conformance zone",IF({outside_rej},"non-conformance zone",'
                    f'"uncertainty range"))')
        elif rule.kind == "specific_risk":
            ok = f"{at('p_c')}>=1-decision_max_pfa"
            outcome = f'=IF({ok},"{cf.CONFORMS}","{cf.DOES_NOT_CONFORM}")'
            zone = f'=IF({ok},"acceptance zone","rejection zone")'
        else:
            outcome = f'=IF({inside_acc},"{cf.CONFORMS}","{cf.DOES_NOT_CONFORM}")'
            zone = f'=IF({inside_acc},"acceptance zone","rejection zone")'
        book.formula(ws, r, c["outcome"], outcome, fmt=None)
        book.formula(ws, r, c["zone"], zone, fmt=None)
        cache[at("outcome")] = d["outcome"]
        cache[at("zone")] = d["zone"]
        # chart data: deviations (µm) from the reference
        ref = f"({lsl}+{usl})/2" if (lsl and usl) else (lsl or usl)
        ref_v = (d["lsl_mm"] + d["usl_mm"]) / 2 if (lsl and usl) else (d["lsl_mm"] if lsl else d["usl_mm"])
        dev = (d["value_mm"] - ref_v) * 1000
        book.formula(ws, r, c["dev_um"], f"=({y}-{ref})*1000", fmt=FMT_UM)
        book.formula(ws, r, c["dev_plus_U_um"], f"={at('dev_um')}+{U}", fmt=FMT_UM)
        book.formula(ws, r, c["dev_minus_U_um"], f"={at('dev_um')}-{U}", fmt=FMT_UM)
        cache.update({at("dev_um"): dev, at("dev_plus_U_um"): dev + d["U_um"], at("dev_minus_U_um"): dev - d["U_um"]})
        for lim, j, name, aname in ((lsl, 0, "lsl_dev_um", "A_L_dev_um"), (usl, 1, "usl_dev_um", "A_U_dev_um")):
            if lim is None:
                continue
            book.formula(ws, r, c[name], f"=({lim}-{ref})*1000", fmt=FMT_UM)
            book.formula(ws, r, c[aname], f"=({acc[j]}-{ref})*1000", fmt=FMT_UM)
            cache[at(name)] = (d["lsl_mm" if j == 0 else "usl_mm"] - ref_v) * 1000
            cache[at(aname)] = (d["acceptance_limits_mm"][j] - ref_v) * 1000
    n = len(spec.tolerances)
    last = h + n
    xs = Reference(ws, min_col=c["item"], min_row=h + 1, max_row=last)

    def ref_of(name):
        return Reference(ws, min_col=c[name], min_row=h + 1, max_row=last)

    series = [ChartSeries("measured value", xs, ref_of("dev_um"), colour="000000"),
              ChartSeries("value + U", xs, ref_of("dev_plus_U_um"), colour="1F77B4"),
              ChartSeries("value − U", xs, ref_of("dev_minus_U_um"), colour="1F77B4"),
              ChartSeries("lower specification limit", xs, ref_of("lsl_dev_um"), colour="D62728", symbol="dash"),
              ChartSeries("upper specification limit", xs, ref_of("usl_dev_um"), colour="D62728", symbol="dash"),
              ChartSeries("lower acceptance limit", xs, ref_of("A_L_dev_um"), colour="2CA02C", symbol="dash"),
              ChartSeries("upper acceptance limit", xs, ref_of("A_U_dev_um"), colour="2CA02C", symbol="dash")]
    book.scatter(ws, f"B{last + 3}", "Measured value ± U against the specification (red) and acceptance (green) "
                 "limits", "item (row of the table)", "deviation from the tolerance midpoint (µm)",
                 series, width=24, height=11, x_min=0)
    for name, width in (("characteristic", 18), ("outcome", 18), ("zone", 22)):
        ws.column_dimensions[col(c[name])].width = width
    book.print_setup(ws, landscape=True, title_rows=h, area=f"A1:{col(c['zone'])}{last + 26}")
    return {SHEET: cache}


def mm_format(U_um: float) -> str:
    """The number format of a row's values and limits in mm: 0.1 µm (FMT_MM), or finer so that
    U below 1 µm still shows its two significant digits (GUM 7.2.6): U = 0.64 µm -> 0.00001 mm."""
    try:
        dec = decimals_for(U_um) + 3
    except ModelError:
        return FMT_MM
    return FMT_MM if dec <= 4 else "0." + "0" * min(dec, 9)


def _inside(y: str, lo: str | None, hi: str | None) -> str:
    parts = ([f"{y}>={lo}"] if lo else []) + ([f"{y}<={hi}"] if hi else [])
    return parts[0] if len(parts) == 1 else f"AND({','.join(parts)})"


def _outside(y: str, lo: str | None, hi: str | None) -> str:
    parts = ([f"{y}<{lo}"] if lo else []) + ([f"{y}>{hi}"] if hi else [])
    return parts[0] if len(parts) == 1 else f"OR({','.join(parts)})"


# -- the way back (`cmmwb read`) ---------------------------------------------------------------------

def read_back(cells, rt) -> None:
    """The Decision sheet's inputs back into ``rt.doc["decision"]`` (``cmmwb read``): r, max_pfa, k
    and each tolerance's limits and measured value, by their defined names.  A value still equal to
    the build-time one keeps the task file's form (``tol_mm`` around ``nominal_mm``); a changed limit
    turns the entry into ``lsl_mm``/``usl_mm``."""
    from openpyxl.utils import get_column_letter

    tbl = rt.doc.get(SECTION)
    # a characteristic task decided without [decision] (the default rule): a k typed in the sheet
    # makes the table
    created = tbl is None and "decision_k" in cells.wb.defined_names
    if created:
        tbl = {}
    if not isinstance(tbl, dict):
        return

    def value(name: str):
        ws, r, c = cells.named(name)
        x = cells.number(ws, r, c, name)
        built = cells.snapshot.get(f"{ws.title}!{get_column_letter(c)}{r}")
        return x, built, cells.where(ws, r, c)

    for key, name in (("r", "decision_r"), ("max_pfa", "decision_max_pfa"), ("k", "decision_k")):
        if name not in cells.wb.defined_names:
            continue
        x, built, where = value(name)
        if key in tbl or built is None or x != built:
            tbl[key] = x
        rt.sources[f"[{SECTION}] {key}"] = where
    if created and tbl:
        rt.doc[SECTION] = tbl
    entries = tbl.get("tolerances")
    if not isinstance(entries, list):
        return
    for n, t in enumerate(entries, start=1):
        if not isinstance(t, dict):
            continue
        got = {}
        for key in ("lsl_mm", "usl_mm", "measured_mm", "s_um", "n_repeats"):
            name = f"tol{n}_{key}"
            if name in cells.wb.defined_names:
                got[key] = value(name)
                rt.sources[_where(n, key)] = got[key][2]
        for key in ("measured_mm", "s_um", "n_repeats"):
            if key in got and got[key][0] != got[key][1]:
                t[key] = got[key][0]
        limits = {k_: v for k_, v in got.items() if k_ in ("lsl_mm", "usl_mm")}
        if any(x != built for x, built, _ in limits.values()):
            t.pop("tol_mm", None)
            t.pop("nominal_mm", None)
            for key, (x, _, where) in limits.items():
                t[key] = x
            rt.sources[_where(n, "tol_mm")] = next(iter(limits.values()))[2]
