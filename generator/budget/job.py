"""The ``budget`` task: sensitivity-analysis uncertainty budgets from E_L,MPE
(Wojtyła, Płowucha et al. 2023, Measurement 222, 113635).

Task file: ``[task]``, ``[mpe]`` (A_um, B_mm, b, k), ``[points]`` (named essential points),
optional ``[datum_system]`` (primary, secondary, tertiary) and ``[[characteristics]]``; the keys
are documented in ``NEW_TASK`` (= ``examples/knuckle.toml``, the paper's steering knuckle).

Workbook (``generator.budget.book``): Instructions, Inputs, one sheet per characteristic in the
layout of the paper's Tables 1-9 (every value, sensitivity, u_i, contribution and u_c a native
formula of the inputs), Results.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from cmmwb.xlfuncs import budget as bd
from cmmwb.xlfuncs import dof
from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.limits import coordinate_problem

from .. import __version__
from ..errors import InputError, model_errors_named
from ..quantities import Cells, Quantity, ToleranceKeys
from ..taskfile import COMMON_TABLES, check_keys, number, place, table, task_kind_and_name, text_list
from ..taskkind import always_exact, no_verdicts
from ..taskworkpiece import read_workpiece
from ..workbook.book import RESULTS, BookAdditions
from ..workbook.xlref import cell, check_name
from .task import MODEL_KEYS, TYPE_A_INPUT, Characteristic, Task, distance_name

KIND = "budget"
EXAMPLES = ["knuckle.toml"]
EXAMPLES_DIR = Path(__file__).resolve().parents[1] / "examples"

#: the commented steering-knuckle task written by ``cmmwb new budget``, named ``my_budget`` like the
#: other kinds' starting tasks (``my_pointcloud``, ``my_feature``, ``my_part``)
NEW_TASK: str = (EXAMPLES_DIR / "knuckle.toml").read_text(encoding="utf-8").replace(
    '\nname = "knuckle" ', '\nname = "my_budget"', 1)
#: the task names no table beside it (its points are in the TOML)
NEW_TASK_FILES: dict[str, str] = {}
#: the task-kind contract's hooks (generator.taskkind): a budget is exact at every size and has no
#: verdict besides its characteristics' decisions
force_exact = always_exact
verdicts = no_verdicts

RESULT_COLUMNS = ["name", "variant", "value_mm", "u_um", "U_um"]

_POINT_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,19}$")
_CHAR_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,30}$")
RESERVED_SHEETS = {"inputs", "results", "instructions", "decision", "summary"}


# -- reading the task file ----------------------------------------------------------------------

def _err(path: Path, where: str, message: str) -> InputError:
    return InputError(message, file=path, where=where)


def _point_names(path: Path, value, n: int, where: str, points: dict) -> str | tuple[str, ...]:
    """``n`` = 1: one point name; ``n`` > 1: a list of ``n`` distinct point names."""
    items = [value] if n == 1 else value
    if n == 1 and not isinstance(value, str):
        raise _err(path, where, f"must be the name of a point, got {value!r}")
    if n > 1 and (not isinstance(value, list) or len(value) != n):
        raise _err(path, where, f"must be a list of {n} point names, got {value!r}")
    for p in items:
        if not isinstance(p, str):
            raise _err(path, where, f"must be point names, got {p!r}")
        if p not in points:
            raise _err(path, where, f"unknown point {p!r} (the [points] table has "
                       f"{', '.join(points) or 'none'})")
    if n > 1 and len(set(items)) != n:
        raise _err(path, where, f"needs {n} different points, got {value!r}")
    return items[0] if n == 1 else tuple(items)


def _read_points(path: Path, doc: dict) -> dict[str, tuple[float, float, float]]:
    tbl = table(path, doc, "points")
    if not tbl:
        raise _err(path, "[points]", "no essential points (write e.g. A = [50, -32, 0])")
    out = {}
    for name, value in tbl.items():
        where = f"[points] {name}"
        if not _POINT_NAME.match(name):
            raise _err(path, where, "a point name starts with a letter and has at most 20 "
                       "letters, digits or underscores")
        if (not isinstance(value, list) or len(value) != 3 or
                any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value)):
            raise _err(path, where, f"must be three numbers [x_mm, y_mm, z_mm], got {value!r}")
        if not all(math.isfinite(float(v)) for v in value):
            raise _err(path, where, f"must be three finite numbers, got {value!r}")
        for v in value:
            if coordinate_problem(float(v)) is not None:
                raise _err(path, where, coordinate_problem(float(v)))
        for ax in "xyz":
            try:
                check_name(f"{name}_{ax}_mm")
            except ValueError:
                raise _err(path, where, "not usable as a workbook name") from None
        out[name] = tuple(float(v) for v in value)
    return out


def _read_datum_system(path: Path, doc: dict, points: dict) -> bd.DatumSystem | None:
    if "datum_system" not in doc:
        return None
    tbl = table(path, doc, "datum_system")
    check_keys(path, tbl, "datum_system", {"primary", "secondary", "tertiary"})
    for key in ("primary", "secondary"):
        if key not in tbl:
            raise _err(path, f"[datum_system] {key}", "missing key")
    primary = _point_names(path, tbl["primary"], 3, "[datum_system] primary", points)
    secondary = _point_names(path, tbl["secondary"], 2, "[datum_system] secondary", points)
    tertiary = None
    if "tertiary" in tbl:
        tertiary = _point_names(path, tbl["tertiary"], 1, "[datum_system] tertiary", points)
    with model_errors_named(path, "[datum_system]"):
        return bd.DatumSystem(primary, secondary, tertiary)


def _read_characteristic(path: Path, n: int, raw, points: dict, ds) -> Characteristic:
    where = f"[[characteristics]] #{n}"
    if not isinstance(raw, dict):
        raise _err(path, where, "must be a table")
    model = raw.get("model")
    if model not in MODEL_KEYS:
        raise _err(path, f"{where} key 'model'",
                   f"must be one of {', '.join(MODEL_KEYS)}, got {model!r}")
    keys = set(MODEL_KEYS[model]) | {"name", "model", "variant"}
    if model == "datum_distance":
        keys.add("datum")
    if model == "position":
        keys |= {"datums", "ted_mm"}
    for key in raw:
        if key not in keys:
            raise _err(path, f"{where} key '{key}'",
                       f"unknown key for model {model!r} (expected {', '.join(sorted(keys))})")
    name = raw.get("name")
    if not isinstance(name, str) or not _CHAR_NAME.match(name):
        raise _err(path, f"{where} key 'name'", "a characteristic name starts with a letter and "
                   f"has at most 31 letters, digits or underscores, got {name!r}")
    if name.lower() in RESERVED_SHEETS:
        raise _err(path, f"{where} key 'name'", f"{name!r} is the name of a workbook sheet")
    pts = {}
    for key, count in MODEL_KEYS[model].items():
        if key not in raw:
            raise _err(path, f"{where} key '{key}'", "missing key")
        pts[key] = _point_names(path, raw[key], count, f"{where} key '{key}'", points)
    if model == "point_point" and pts["from"] == pts["to"]:
        raise _err(path, f"{where} key 'to'", "the two points are the same")
    if model == "point_line" and pts["point"] in pts["line"]:
        raise _err(path, f"{where} key 'point'", "the point is one of the line's points")
    if model == "point_plane" and pts["point"] in pts["plane"]:
        raise _err(path, f"{where} key 'point'", "the point is one of the plane's points")
    c = Characteristic(n, name, model, pts)
    if model in ("datum_distance", "position") and ds is None:
        raise _err(path, f"{where} key 'model'", f"model {model!r} needs a [datum_system] table")
    if model == "datum_distance":
        datum = raw.get("datum")
        if datum not in bd.DATUMS:
            raise _err(path, f"{where} key 'datum'",
                       f"must be one of {', '.join(bd.DATUMS)}, got {datum!r}")
        c.datum = datum
    variant = raw.get("variant", "auto")
    if model == "position":
        datums = raw.get("datums")
        if (not isinstance(datums, list) or len(datums) != 2 or
                any(d not in bd.DATUMS for d in datums) or datums[0] == datums[1]):
            raise _err(path, f"{where} key 'datums'", "must be two different datums of "
                       f"{', '.join(bd.DATUMS)}, e.g. [\"primary\", \"tertiary\"], got {datums!r}")
        c.datums = tuple(datums)
        ted = raw.get("ted_mm")
        if (not isinstance(ted, list) or len(ted) != 2 or
                any(isinstance(t, bool) or not isinstance(t, (int, float)) for t in ted) or
                not all(math.isfinite(float(t)) and float(t) >= 0 for t in ted)):
            raise _err(path, f"{where} key 'ted_mm'", "must be the two theoretically exact "
                       f"distances (mm, >= 0) from the two datums, got {ted!r}")
        c.ted_mm = (float(ted[0]), float(ted[1]))
        if isinstance(variant, list):
            if len(variant) != 2 or not all(isinstance(v, str) for v in variant):
                raise _err(path, f"{where} key 'variant'",
                           f"must be \"auto\" or one variant per distance, got {variant!r}")
            variant = tuple(variant)
        elif not isinstance(variant, str):
            raise _err(path, f"{where} key 'variant'", f"must be text, got {variant!r}")
        for k in (1, 2):
            check_name(f"{name}_ted{k}_mm")
    elif not isinstance(variant, str):
        raise _err(path, f"{where} key 'variant'", f"must be text, got {variant!r}")
    c.variant = variant
    return c


def load(path: Path, doc: dict) -> Task:
    """Read and validate a budget task; every characteristic is evaluated once so that
    degenerate geometry is reported with its ``[[characteristics]]`` entry."""
    path = Path(path)
    kind, name = task_kind_and_name(path, doc)
    if kind != KIND:
        raise _err(path, "[task] kind", f"expected {KIND!r}, got {kind!r}")
    check_keys(path, doc, "task file", {"task", "mpe", "points", "datum_system", "characteristics"} | COMMON_TABLES)
    task_tbl = table(path, doc, "task")
    check_keys(path, task_tbl, "task", {"kind", "name", "notes"})
    notes = text_list(path, task_tbl, "task", "notes")
    m = table(path, doc, "mpe")
    check_keys(path, m, "mpe", {"A_um", "B_mm", "b", "k"})
    mpe = bd.MPE(number(path, m, "mpe", "A_um", lo=0.0), number(path, m, "mpe", "B_mm", positive=True),
                 number(path, m, "mpe", "b", positive=True), number(path, m, "mpe", "k", 2.0, positive=True))
    points = _read_points(path, doc)
    ds = _read_datum_system(path, doc, points)
    raw = doc.get("characteristics")
    if not isinstance(raw, list) or not raw:
        raise _err(path, "[[characteristics]]", "no characteristics (add [[characteristics]] tables)")
    chars = []
    seen: dict[str, int] = {}
    for n, entry in enumerate(raw, start=1):
        c = _read_characteristic(path, n, entry, points, ds)
        if c.name.lower() in seen:
            first = place(path, f"[[characteristics]] #{seen[c.name.lower()]} key 'name'")
            raise _err(path, f"{c.where} key 'name'",
                       f"{c.name!r} is also the name of characteristic #{seen[c.name.lower()]} (at {first}; "
                       "names are sheet names: letter case aside, each is another)")
        seen[c.name.lower()] = n
        chars.append(c)
    wp = read_workpiece(path, doc)
    part = None if wp is None else bd.Part(wp.workpiece, **wp.u)
    task = Task(path, name, mpe, points, ds, chars, list(notes), part)
    for c in chars:
        _evaluate(task, c)      # degenerate geometry, unknown variants -> InputError here
    return task


# -- computing ------------------------------------------------------------------------------------

def specs(task: Task, c: Characteristic, datum: str | None = None) -> list[bd.VariantSpec]:
    """The formula variants of a distance characteristic (or of one datum of a position)."""
    if c.model == "position":
        return bd.variants_datum(c.points["point"], datum, task.datum_system)
    g = dict(c.points)
    if c.model == "datum_distance":
        g["datum"] = c.datum
    return bd.specs_for(c.model, points_used=g, datums=task.datum_system)


def _evaluate(task: Task, c: Characteristic):
    """DistanceBudget or PositionBudget of one characteristic (ModelError -> InputError)."""
    try:
        if c.model == "position":
            return bd.position_budget(c.points["point"], c.datums, c.ted_mm, task.datum_system,
                                      task.points, task.mpe, c.variant, task.part)
        return bd.distance_budget(specs(task, c), task.points, task.mpe, c.variant, task.part)
    except ModelError as e:
        where = f"{c.where} key 'variant'" if "unknown variant" in str(e) else c.where
        raise InputError(f"{c.name}: {e}", file=task.path, where=where) from None


def evaluate(task: Task) -> list:
    """The evaluated budget of every characteristic, in task order."""
    return [_evaluate(task, c) for c in task.characteristics]


def _mpe_rows(v: bd.VariantBudget, b: float) -> list[dict]:
    """A variant's budget rows with the distribution b implies and ν = ∞ (JSON null): type B
    inputs from an MPE statement (GUM G.4.2, G.4.3; docs/cli.md)."""
    dist = dof.distribution_of_b(b)
    return [dict(row, distribution=dist, nu=None) for row in v.rows()]


def _thermal(v: bd.VariantBudget) -> dict:
    """The factor W of a budget (docs/workpiece.md; only with [workpiece]): its rows (value in
    ``unit``, sensitivity µm per unit, u in ``unit``, contribution µm, distribution, ν = ∞) and the
    two parts of u: ``u_mpe_um`` (the MPE inputs, eq. (6)) and ``u_W_um``."""
    if not v.thermal:
        return {}
    return {"workpiece_rows": [dict(row, nu=None) for row in v.thermal], "u_mpe_um": v.u_mpe_um,
            "u_W_um": v.u_W_um}


def _distance_entry(name: str, model: str, d: bd.DistanceBudget, b: float) -> dict:
    ch = d.chosen
    return {
        "name": name, "model": model, "variant": ch.label, "equation": ch.spec.equation,
        "value_mm": ch.value_mm, "u_um": ch.u_c_um, "U_um": ch.U_um, "rows": _mpe_rows(ch, b),
        **_thermal(ch),
        "variants": [{"variant": v.label, "equation": v.spec.equation, "value_mm": v.value_mm,
                      "u_um": v.u_c_um, "U_um": v.U_um, "rows": _mpe_rows(v, b), **_thermal(v), "nu_eff": None}
                     for v in d.variants],
        "nu_eff": None,
    }


#: the distribution of a position's inputs l_1, l_2: each is the combination of its distance
#: budget's inputs (GUM G.2: close to normal), with that budget's ν_eff
POSITION_INPUT_DISTRIBUTION = "normal"


def type_a(results: dict) -> dict[str, dict]:
    """The type A repeatabilities the ``[[decision.tolerances]]`` give, per characteristic name:
    {"tolerance": its 1-based number, "u_um": u_A, "nu": ν_A, "k_from_dof": bool} (the first
    tolerance with s_um of a characteristic; GUM 4.2.3, G.3.3)."""
    out: dict[str, dict] = {}
    kfd = bool(results.get("decision_rule", {}).get("k_from_dof", False))
    for n, d in enumerate(results.get("decisions", []), start=1):
        if d.get("u_A_um") is not None and d["characteristic"] not in out:
            out[d["characteristic"]] = {"tolerance": n, "u_um": d["u_A_um"], "nu": d["nu_A"],
                                        "k_from_dof": kfd}
    return out


def add_type_a(results: dict) -> None:
    """After the decisions: a characteristic with a type A repeatability gets ``type_a`` (the row
    of its budget: input, u_um, distribution "normal", nu = n - 1) and its ``nu_eff`` by
    Welch–Satterthwaite over its contributions (GUM G.4.1; the MPE inputs ν = ∞), the combined
    ``u_with_type_a_um``, ``k`` (t_95.45(⌊ν_eff⌋) with ``[decision] k_from_dof``, GUM G.6.4,
    else the task's k) and ``U_with_type_a_um``.  Existing fields do not change."""
    k_task = float(results["mpe"]["k"])
    given = type_a(results)
    for ch in results["characteristics"]:
        a = given.get(ch["name"])
        if a is None:
            continue
        contributions = [ch["u_um"], a["u_um"]]
        u = math.hypot(*contributions)
        nu = dof.nu_eff(contributions, [math.inf, a["nu"]])
        k = dof.coverage_factor(nu) if a["k_from_dof"] else k_task
        ch["type_a"] = {"input": TYPE_A_INPUT, "tolerance": a["tolerance"], "u_um": a["u_um"],
                        "distribution": "normal", "nu": a["nu"], "u_with_type_a_um": u, "k": k,
                        "U_with_type_a_um": k * u}
        ch["nu_eff"] = nu
        for v in ch.get("variants", []):
            if v["variant"] == ch["variant"]:      # the chosen budget carries the type A row
                v["nu_eff"] = nu


def compute(task: Task) -> dict:
    """Results JSON per the contract (plus per-variant budgets, equations, and for positions the
    two distance budgets)."""
    out = {"name": task.name, "kind": KIND, "version": __version__,
           "mpe": {"A_um": task.mpe.A_um, "B_mm": task.mpe.B_mm, "b": task.mpe.b, "k": task.mpe.k},
           "characteristics": []}
    for c, r in zip(task.characteristics, evaluate(task)):
        if c.model == "position":
            entry = {
                "name": c.name, "model": c.model, "variant": r.variant, "point": r.point,
                "datums": list(r.datums), "ted_mm": list(r.ted_mm),
                "value_mm": r.value_mm, "u_um": r.u_um, "U_um": r.U_um,
                "rows": [dict(row, distribution=POSITION_INPUT_DISTRIBUTION, nu=None) for row in r.rows()],
                "u_eq26_um": r.u_eq26_um,
                **({"u_mpe_um": 2.0 * math.hypot(*(d.chosen.u_mpe_um for d in r.distances)),
                    "u_W_um": 2.0 * math.hypot(*(d.chosen.u_W_um for d in r.distances))}
                   if task.part is not None else {}),
                "distances": [dict(_distance_entry(distance_name(c, i), "datum_distance", d,
                                                   task.mpe.b), datum=r.datums[i])
                              for i, d in enumerate(r.distances)],
                "nu_eff": None,
            }
        else:
            entry = _distance_entry(c.name, c.model, r, task.mpe.b)
            entry.update({k: (list(v) if isinstance(v, tuple) else v) for k, v in c.points.items()})
            if c.datum:
                entry["datum"] = c.datum
        out["characteristics"].append(entry)
    return out


# -- outputs ----------------------------------------------------------------------------------------

def write_book(task: Task, results: dict, path: Path, additions: BookAdditions | None = None) -> None:
    from .book import write

    write(task, evaluate(task), path, type_a=type_a(results), additions=additions)


def write_plots(task: Task, results: dict, out_dir: Path) -> list[Path]:
    """One PNG: per characteristic, the non-zero contributions of its chosen budget (for a
    position, each distance's contributions times the sensitivity 2 of u_POS)."""
    from ..workbook.plots import pyplot

    plt = pyplot()
    chars = results["characteristics"]
    n = len(chars)
    ncols = 2 if n > 1 else 1
    nrows = (n + ncols - 1) // ncols
    fig, axes = plt.subplots(nrows, ncols, figsize=(6.2 * ncols, 2.6 * nrows + 0.6), dpi=100,
                             squeeze=False)
    for ax, ch in zip(axes.flat, chars):
        labels, values = [], []
        if ch["model"] == "position":
            for i, d in enumerate(ch["distances"]):
                for row in d["rows"]:
                    labels.append(f"l{i + 1}: {row['input']}")
                    values.append(2.0 * abs(row["contribution_um"]))
        else:
            for row in ch["rows"]:
                labels.append(row["input"])
                values.append(abs(row["contribution_um"]))
        keep = [(lab, v) for lab, v in zip(labels, values) if v > 1e-3]
        keep = keep or list(zip(labels, values))[:1]
        ax.barh([k[0] for k in keep][::-1], [k[1] for k in keep][::-1], color="#4472C4")
        ax.set_title(f"{ch['name']}: u = {ch['u_um']:.3f} µm ({ch['variant'][:60]})", fontsize=8)
        ax.set_xlabel("|contribution| / µm", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(axis="x", alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.suptitle(f"{results['name']}: uncertainty contributions (Wojtyła/Płowucha 2023)", fontsize=10)
    fig.tight_layout()
    path = Path(out_dir) / f"{task.name}_contributions.png"
    fig.savefig(path)
    plt.close(fig)
    return [path]


# -- the records of the results (generator.quantities) -----------------------------------------

#: a [[decision.tolerances]] entry names a characteristic by its name
TOLERANCE_KEYS = ToleranceKeys(("characteristic",), help="characteristic = the name of a [[characteristics]] entry")
VALUE_SOURCE = ("evaluated at the essential points of the task file ([points]: the nominal geometry, "
                "not a measurement)")
U_SOURCE = "the budget of the MPE statement E = A + L/B (Wojtyła/Płowucha 2023), type B only"


def quantities(task: Task, results: dict, k: float = 2.0) -> list[Quantity]:
    """One record per characteristic (its Results row): the value the task's points give and u, U
    of its chosen budget with the task's k (the named input ``k``); ``k`` is not used."""
    k_task = float(results["mpe"]["k"])
    out = []
    for i, c in enumerate(results["characteristics"]):
        r = i + 2
        out.append(Quantity(label=c["name"], value=c["value_mm"], unit="mm", u=c["u_um"], u_unit="µm", k=k_task,
                            U_unit="µm", ident={"characteristic": c["name"]}, value_source=VALUE_SOURCE,
                            u_source=U_SOURCE,
                            cells=Cells(RESULTS, r, cell(r, 3, RESULTS), cell(r, 4, RESULTS), cell(r, 5, RESULTS),
                                        k="k")))
    return out


def read_book(cells, rt, points_file: str) -> None:
    """The way back (``cmmwb read``): :func:`generator.budget.reader.read_budget` (the essential
    points are in the task file, ``points_file`` is not used)."""
    from .reader import read_budget

    read_budget(cells, rt)


def summary(results: dict) -> list[str]:
    chars = results["characteristics"]
    pos = [c for c in chars if c["model"] == "position"]
    lines = [f"{len(chars)} characteristics; E = {results['mpe']['A_um']:g} + L/"
             f"{results['mpe']['B_mm']:g} µm, b = {results['mpe']['b']:g}, k = {results['mpe']['k']:g}"]
    if pos:
        lines.append("position u_POS / U_POS (µm): " + ", ".join(
            f"{c['name']} {c['u_um']:.2f} / {c['U_um']:.2f}" for c in pos))
    rest = [c for c in chars if c["model"] != "position"]
    if rest:
        lines.append("u_c (µm): " + ", ".join(f"{c['name']} {c['u_um']:.3f}" for c in rest[:6])
                     + (" ..." if len(rest) > 6 else ""))
    return lines
