"""The ``characteristic`` task: the characteristics of a drawing (size, distance, angle, form,
orientation, position at MMC/LMC) from several least-squares features fitted in one task, with
their uncertainty under the full point-cloud V_X of Forbes 2025 (xlfuncs.characteristics).

Task file::

    [task]              kind = "characteristic", name, notes
    [points]            file = "points.csv"    (id,x,y,z,nx,ny,nz,probe)  -- or -- rows
    [parameters], [[probes]]                    the point-cloud model (Forbes 2025 Table 3 names)
    [[features]]        name, type (line | plane | circle | sphere | cylinder | cone),
                        ids = [...] or id_prefix = "H1.", circle_plane, axis_hint
    [[frames]]          name, primary, secondary, tertiary      (datum reference frames)
    [[characteristics]] name, type, features = [...], method (LS | MZ), frame, datum, nominal,
                        nominal_position_mm, zone (planar | diametral), material_condition
                        (RFS | MMC | LMC), size, internal, direction, lsl, usl, tolerance_mm,
                        measured (the value measured elsewhere: the points then give only u)

    [decision]          rule, r, max_pfa, k   (optional; ISO 14253-1 and k = 2 when absent)
    [report]            lab, operator, cmm, artefact, job_id, notes

Every characteristic with a tolerance is decided by the build (generator.decision: the
characteristic kind's tolerances, docs/conformity.md): 'Decision' and 'Summary' sheets, the JSON
``decisions``; angles (deg) are not decided yet (JSON ``not_decided``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from cmmwb.xlfuncs import characteristics as ch
from cmmwb.xlfuncs import features as ft
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.limits import coordinate_problem

from .. import __version__
from ..errors import InputError
from ..quantities import Cells, Quantity, ToleranceKeys
from ..taskcloud import check_label, read_point_cloud
from ..taskfile import COMMON_TABLES, Names, check_keys, number, string, table, task_kind_and_name, text_list, vector3
from ..taskkind import always_exact, no_type_a, no_verdicts
from ..workbook.book import RESULTS, BookAdditions
from ..workbook.xlref import cell

KIND = "characteristic"
EXAMPLES = ["characteristic_plate.toml", "housing_W.toml"]
#: the task-kind contract's hooks (generator.taskkind): exact at every size, no type A inputs
force_exact = always_exact
add_type_a = no_type_a
verdicts = no_verdicts

FEATURE_KEYS = {"name", "type", "ids", "id_prefix", "circle_plane", "axis_hint"}
FRAME_KEYS = {"name", "primary", "secondary", "tertiary"}
CHAR_KEYS = {"name", "type", "features", "method", "frame", "datum", "nominal",
             "nominal_position_mm", "zone", "material_condition", "size", "internal",
             "direction", "lsl", "usl", "tolerance_mm", "measured"}


@dataclass
class Task:
    name: str
    notes: list[str]
    cloud: pc.PointCloud
    params: pc.Parameters
    features: list[ch.FeatureSpec]
    frames: list[ch.FrameSpec]
    characteristics: list[ch.CharacteristicSpec]
    path: Path
    points_file: str | None = None
    #: (joint fit, results, V_X components), computed once by :func:`fitted`
    cache: tuple | None = field(default=None, repr=False, compare=False)


def _array_of_tables(path, doc, key, required=True):
    raw = doc.get(key)
    if raw is None:
        if required:
            raise InputError(f"missing [[{key}]]", file=path, where=f"[[{key}]]")
        return []
    if not isinstance(raw, list) or not all(isinstance(t, dict) for t in raw):
        raise InputError(f"must be one or more [[{key}]] tables", file=path, where=f"[[{key}]]")
    return raw


def _names(path, tbl, section, key):
    v = tbl.get(key)
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
        raise InputError("must be a feature name or a list of feature names", file=path,
                         where=f"{section} {key}")
    return tuple(v)


#: the keys of a [[characteristics]] entry beyond name, type, features, and the types that use
#: each (a key given to a type that does not use it is refused: it would be dropped silently)
APPLIES = {
    "method": ch.FORM_TYPES + ch.ORIENTATION_TYPES,
    "frame": ch.ORIENTATION_TYPES + ("position",),
    "datum": ch.ORIENTATION_TYPES,
    "nominal": ch.SIZE_TYPES + ("distance", "angle", "angularity"),
    "nominal_position_mm": ("position",),
    "zone": ch.ORIENTATION_TYPES + ("position",),
    "material_condition": ("position",),
    "size": ("position",),
    "internal": ("position",),
    "direction": ("straightness",),
    "lsl": ch.SIZE_TYPES + ("distance", "angle"),
    "usl": ch.SIZE_TYPES + ("distance", "angle"),
    "tolerance_mm": ("diameter", "width", "distance") + ch.FORM_TYPES + ch.ORIENTATION_TYPES + ("position",),
}
#: the features a characteristic type takes
FEATURE_COUNT = {"width": 2, "distance": 2, "angle": 2}
#: the values of the keys with a fixed set of them
CHOICES = {"method": ("LS", "MZ"), "zone": ("planar", "diametral"), "material_condition": ("RFS", "MMC", "LMC")}
#: the smallest number of points of a feature whose minimum zone is asked for (xlfuncs.minzone:
#: k free zone parameters need k + 2 points)
MZ_MIN_POINTS = {"straightness": 3, "flatness": 4, "roundness": 4, "cylindricity": 6}


def _read_features(path, doc, labels, index) -> tuple[list[ch.FeatureSpec], list[str]]:
    feats, places = [], []
    names = Names(path, "feature")
    for n, t in enumerate(_array_of_tables(path, doc, "features"), start=1):
        sec = f"[[features]] #{n}"
        check_keys(path, t, sec, FEATURE_KEYS)
        fname = names.add(check_label(string(path, t, sec, "name"), path, f"{sec} name"), f"{sec} name")
        el = string(path, t, sec, "type")
        if el not in ft.ELEMENTS:
            raise InputError(f"unknown feature type {el!r}; known: {', '.join(ft.ELEMENTS)}",
                             file=path, where=f"{sec} type")
        if ("ids" in t) == ("id_prefix" in t):
            raise InputError("give either ids = [...] or id_prefix", file=path, where=sec)
        if "ids" in t:
            ids = t["ids"]
            if not isinstance(ids, list) or not all(isinstance(i, str) for i in ids):
                raise InputError("must be a list of point ids", file=path, where=f"{sec} ids")
            bad = [i for i in ids if i not in index]
            if bad:
                raise InputError(f"unknown point id {bad[0]!r}", file=path, where=f"{sec} ids")
            twice = next((i for k, i in enumerate(ids) if i in ids[:k]), None)
            if twice is not None:
                raise InputError(f"point id {twice!r} is listed twice", file=path, where=f"{sec} ids")
            idx = tuple(index[i] for i in ids)
        else:
            pre = string(path, t, sec, "id_prefix")
            idx = tuple(i for i, lab in enumerate(labels) if lab.startswith(pre))
            if not idx:
                raise InputError(f"no point id starts with {pre!r}", file=path,
                                 where=f"{sec} id_prefix")
        plane = t.get("circle_plane", "xy")
        if plane not in ("xy", "yz", "zx", "space"):
            raise InputError("must be xy, yz, zx or space", file=path, where=f"{sec} circle_plane")
        hint = vector3(path, t, sec, "axis_hint") if "axis_hint" in t else None
        feats.append(ch.FeatureSpec(fname, el, idx, None if plane == "space" else plane, hint))
        places.append(sec)
    return feats, places


def _read_frames(path, doc, features: dict[str, ch.FeatureSpec]) -> tuple[list[ch.FrameSpec], list[str], Names]:
    """The datum reference frames: each names its datum features (in order of precedence), each
    feature once; the primary is a plane (xlfuncs.datums)."""
    frames, places = [], []
    names = Names(path, "datum frame")
    for n, t in enumerate(_array_of_tables(path, doc, "frames", required=False), start=1):
        sec = f"[[frames]] #{n}"
        check_keys(path, t, sec, FRAME_KEYS)
        fname = names.add(check_label(string(path, t, sec, "name"), path, f"{sec} name"), f"{sec} name")
        datums: dict[str, str] = {}
        for key in ("primary", "secondary", "tertiary"):
            if key not in t:
                if key == "primary":
                    string(path, t, sec, key)      # the missing-key message
                continue
            if key == "tertiary" and "secondary" not in t:
                raise InputError("a tertiary datum needs a secondary datum", file=path, where=f"{sec} tertiary")
            v = t[key]
            if not isinstance(v, str):
                raise InputError(f"must be the name of one datum feature (text), got {v!r}", file=path,
                                 where=f"{sec} {key}")
            if v not in features:
                raise InputError(f"unknown feature {v!r}; the [[features]] are {', '.join(features) or 'none'}",
                                 file=path, where=f"{sec} {key}")
            if v in datums.values():
                other = next(k for k, x in datums.items() if x == v)
                raise InputError(f"feature {v!r} is already the {other} datum of frame {fname!r}; each datum "
                                 "of a frame is another feature", file=path, where=f"{sec} {key}")
            datums[key] = v
        if features[datums["primary"]].element != "plane":
            raise InputError(f"the primary datum {datums['primary']!r} is a "
                             f"{features[datums['primary']].element}; it must be a plane", file=path,
                             where=f"{sec} primary")
        frames.append(ch.FrameSpec(fname, datums["primary"], datums.get("secondary"), datums.get("tertiary")))
        places.append(sec)
    return frames, places, names


def _tolerance_number(path, t, sec, key, lo_zero: bool) -> float:
    v = number(path, t, sec, key)
    problem = coordinate_problem(v)
    if problem is not None:
        raise InputError(problem, file=path, where=f"{sec} {key}")
    if lo_zero and v < 0:
        raise InputError(f"a zone width cannot be negative, got {v:g} mm", file=path, where=f"{sec} {key}")
    return v


def _read_characteristics(path, doc, features: dict[str, ch.FeatureSpec], frames: Names,
                          ) -> tuple[list[ch.CharacteristicSpec], list[str]]:
    chars, places = [], []
    names = Names(path, "characteristic")
    raw = _array_of_tables(path, doc, "characteristics")
    for n, t in enumerate(raw, start=1):
        sec = f"[[characteristics]] #{n}"
        check_keys(path, t, sec, CHAR_KEYS)
        cname = names.add(check_label(string(path, t, sec, "name"), path, f"{sec} name"), f"{sec} name")
        typ = string(path, t, sec, "type")
        if typ not in ch.TYPES:
            raise InputError(f"unknown type {typ!r}; known: {', '.join(ch.TYPES)}", file=path, where=f"{sec} type")
        for key, types in APPLIES.items():
            if key in t and typ not in types:
                raise InputError(f"a {typ} takes no {key} (it applies to: {', '.join(types)}); a value "
                                 "here would be ignored: leave it out", file=path, where=f"{sec} {key}")
        feats = _names(path, t, sec, "features")
        need = FEATURE_COUNT.get(typ, 1)
        if len(feats) != need:
            raise InputError(f"a {typ} takes {need} feature{'s' if need > 1 else ''}, got {len(feats)}",
                             file=path, where=f"{sec} features")
        for f in feats:
            if f not in features:
                raise InputError(f"unknown feature {f!r}; the [[features]] are {', '.join(features)}",
                                 file=path, where=f"{sec} features")
        kw: dict = {}
        for k in ("nominal", "lsl", "usl", "measured"):
            if k in t:
                kw[k] = _tolerance_number(path, t, sec, k, lo_zero=False)
        if "lsl" in kw and "usl" in kw and not kw["lsl"] < kw["usl"]:
            raise InputError(f"{cname}: the lower limit lsl = {kw['lsl']:g} must be below the upper usl = "
                             f"{kw['usl']:g}",
                             file=path, where=f"{sec} lsl")
        if "tolerance_mm" in t:
            kw["tolerance_mm"] = _tolerance_number(path, t, sec, "tolerance_mm", lo_zero=True)
        for k in ("method", "frame", "datum", "zone", "material_condition", "size"):
            if k in t:
                kw[k] = string(path, t, sec, k)
                if k in CHOICES and kw[k] not in CHOICES[k]:
                    raise InputError(f"must be {' or '.join(CHOICES[k])}, got {kw[k]!r}", file=path,
                                     where=f"{sec} {k}")
        if "frame" in kw and kw["frame"] not in frames:
            raise InputError(f"unknown datum frame {kw['frame']!r}; the [[frames]] are "
                             f"{', '.join(frames.first) or 'none'}", file=path, where=f"{sec} frame")
        if "datum" in kw:
            if kw["datum"] not in features:
                raise InputError(f"unknown feature {kw['datum']!r}", file=path, where=f"{sec} datum")
            if "frame" in kw:
                raise InputError("give the datum feature or the frame, not both", file=path, where=f"{sec} datum")
        if typ in ch.ORIENTATION_TYPES and "frame" not in kw and "datum" not in kw:
            raise InputError(f"a {typ} needs its datum: frame = a [[frames]] name, or datum = a feature",
                             file=path, where=sec)
        if "tolerance_mm" in kw and ("lsl" in kw or "usl" in kw):
            raise InputError("give either lsl/usl or tolerance_mm, not both", file=path,
                             where=f"{sec} tolerance_mm")
        if typ == "position":
            for key in ("frame", "nominal_position_mm"):
                if key not in t:
                    raise InputError("a position needs its datum frame (frame = a [[frames]] name) and its "
                                     "true position (nominal_position_mm, frame coordinates)", file=path,
                                     where=f"{sec} {key}")
            if kw.get("zone", "diametral") != "diametral":
                raise InputError("a position's zone is diametral (a cylinder about the true position)",
                                 file=path, where=f"{sec} zone")
            mc = kw.get("material_condition", "RFS")
            if mc != "RFS" and "size" not in kw:
                raise InputError(f"a position at {mc} takes its bonus from the size of its feature: give size "
                                 "= the name of that diameter characteristic", file=path,
                                 where=f"{sec} material_condition")
            if mc == "RFS" and ("size" in kw or "internal" in t):
                key = "size" if "size" in kw else "internal"
                raise InputError(f"{key} gives the bonus of a position at MMC or LMC; this one is RFS (give "
                                 "material_condition)", file=path, where=f"{sec} {key}")
            if "size" in kw:
                s = next((x for x in raw if isinstance(x, dict) and x.get("name") == kw["size"]), None)
                if s is None or s.get("type") != "diameter" or not ("lsl" in s and "usl" in s):
                    raise InputError(f"size must name a diameter characteristic with lsl and usl (the size "
                                     f"limits the bonus comes from), got {kw['size']!r}", file=path,
                                     where=f"{sec} size")
                if tuple(_names(path, s, sec, "features")) != feats:
                    raise InputError(f"the size {kw['size']!r} is of feature {s.get('features')!r}, this position "
                                     f"of {feats[0]!r}: the bonus comes from the same feature's size", file=path,
                                     where=f"{sec} size")
            if "tolerance_mm" in kw and kw["tolerance_mm"] == 0 and mc == "RFS":
                raise InputError("a zone of width 0 is only meaningful at MMC or LMC (zero tolerance, the bonus "
                                 "is the zone); at RFS nothing could conform", file=path,
                                 where=f"{sec} tolerance_mm")
        elif kw.get("tolerance_mm") == 0:
            raise InputError(f"a zone of width 0: no {typ} could conform", file=path, where=f"{sec} tolerance_mm")
        if "internal" in t:
            if not isinstance(t["internal"], bool):
                raise InputError("must be true or false", file=path, where=f"{sec} internal")
            kw["internal"] = t["internal"]
        if "direction" in t:
            kw["direction"] = vector3(path, t, sec, "direction")
        if typ == "straightness" and "direction" not in kw:
            raise InputError("a straightness needs its zone direction (direction = the surface's normal)",
                             file=path, where=sec)
        if "nominal_position_mm" in t:
            v = t["nominal_position_mm"]
            if (not isinstance(v, list) or len(v) not in (2, 3) or
                    not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
                raise InputError(f"must be two or three numbers (frame coordinates, mm), got {v!r}",
                                 file=path, where=f"{sec} nominal_position_mm")
            for k, x in enumerate(v):     # nan, inf, 1e300: the coordinate's own problem, not 'not numbers'
                problem = coordinate_problem(float(x))
                if problem:
                    raise InputError(f"{'xyz'[k]}: {problem}", file=path,
                                     where=f"{sec} nominal_position_mm")
            kw["nominal_position_mm"] = tuple(float(x) for x in v)
        if typ in MZ_MIN_POINTS and kw.get("method") == "MZ":
            m = len(features[feats[0]].indices)
            if m < MZ_MIN_POINTS[typ]:
                raise InputError(f"the minimum zone of a {typ} needs at least {MZ_MIN_POINTS[typ]} points; "
                                 f"feature {feats[0]!r} has {m}", file=path, where=f"{sec} method")
        chars.append(ch.CharacteristicSpec(cname, typ, feats, **kw))
        places.append(sec)
    margins = {margin_label(c.name): c.name for c in chars
               if c.type == "position" and c.material_condition != "RFS"}
    for c, sec in zip(chars, places):
        if c.name in margins:
            raise InputError(f"{c.name!r} is the name of the margin of position {margins[c.name]!r} (decided at "
                             f"its material condition); give this characteristic another name", file=path,
                             where=f"{sec} name")
    return chars, places


def load(path: Path, doc: dict) -> Task:
    _, name = task_kind_and_name(path, doc)
    notes = text_list(path, table(path, doc, "task"), "task", "notes")
    check_keys(path, doc, "file", {"task", "points", "parameters", "probes", "features", "frames",
                                   "characteristics"} | COMMON_TABLES)
    cloud, params, tbl = read_point_cloud(path, doc)
    labels = list(cloud.labels)
    index = {lab: i for i, lab in enumerate(labels)}
    feats, feat_places = _read_features(path, doc, labels, index)
    by_name = {f.name: f for f in feats}
    frames, frame_places, frame_names = _read_frames(path, doc, by_name)
    chars, char_places = _read_characteristics(path, doc, by_name, frame_names)
    pts = table(path, doc, "points")
    task = Task(name, notes, cloud, params, feats, frames, chars, Path(path),
                pts.get("file") if isinstance(pts.get("file"), str) else None)
    places = {"features": feat_places, "frames": frame_places, "characteristics": char_places}
    try:
        fitted(task)
    except ModelError as e:
        item = getattr(e, "item", None)
        where = places[item[0]][item[1]] if item is not None and item[0] in places else None
        raise InputError(str(e), file=path, where=where) from None
    return task


def fitted(task: Task):
    """(joint fit, results with u, V_X components) of a task; computed once per task."""
    if task.cache is None:
        jf = ch.fit_features(task.cloud.X_mm, task.cloud.N, task.features)
        V = pc.V_X_components(task.cloud, task.params)
        task.cache = (jf, ch.evaluate(jf, task.frames, task.characteristics, V), V)
    return task.cache


def _row(r: ch.Result) -> dict:
    c = r.spec
    out = {
        "name": c.name, "type": c.type,
        "method": c.method if c.type in ch.FORM_TYPES + ch.ORIENTATION_TYPES else None,
        "features": list(c.features), "frame": c.frame,
        "value": r.value, "unit": r.unit, "u": r.u, "u_unit": r.u_unit,
        "smooth": bool(r.smooth),
        "components": {k: v for k, v in r.u_factors.items()},
        "nominal": c.nominal, "lsl": c.lsl, "usl": c.usl, "tolerance_mm": c.tolerance_mm,
        "material_condition": c.material_condition,
        "bonus_mm": r.bonus_mm, "zone_mm": r.zone_mm, "margin_mm": r.margin_mm,
        "u_margin_um": r.u_margin_um,
        "contact_points": [],
        # issue 33: a value measured elsewhere (a QIF file's) decided with the u of these points
        "value_source": "measured" if c.measured is not None else "points",
        "points_value": r.points_value,
    }
    return out


def compute(task: Task) -> dict:
    jf, res, V = fitted(task)
    rows = []
    for r in res:
        row = _row(r)
        row["contact_points"] = [task.cloud.labels[i] for i in r.active]
        rows.append(row)
    feats = {}
    for name, f in jf.fits.items():
        feats[name] = {"type": f.element, "m": f.m, "parameters": f.values_dict(),
                       "rms_residual_um": f.rms_mm * 1e3}
    return {"kind": KIND, "name": task.name, "version": __version__, "notes": task.notes,
            "features": feats, "parameter_names": list(jf.param_names),
            "characteristics": rows}


def write_book(task: Task, results: dict, path: Path, additions: BookAdditions | None = None) -> None:
    from .book import write_characteristic_book

    jf, res, V = fitted(task)
    write_characteristic_book(task, results, path, jf, res, V, additions)


def write_plots(task: Task, results: dict, out_dir: Path) -> list[Path]:
    from ..workbook.plots import factor_share_plot

    rows = results["characteristics"]
    shares = {fac: [(r["components"].get(fac, 0.0) / r["u"]) ** 2 if r["u"] > 0 else 0.0 for r in rows]
              for fac in pc.FACTORS}
    return [factor_share_plot([r["name"] for r in rows], shares,
                              f"{results['name']}: {len(rows)} characteristics",
                              out_dir / f"{task.name}_factors.png", width=7.5, row_height=0.38,
                              top_down=True, legend_y=1.06)]


def summary(results: dict) -> list[str]:
    """One line per characteristic: the value in the unit of the JSON and the decisions (mm, deg),
    u in µm or µrad, so that a quantity is never shown in two units."""
    lines = []
    given = [r["name"] for r in results["characteristics"] if r.get("value_source") == "measured"]
    if given:
        lines.append(f"{len(given)} of {len(results['characteristics'])} values are measured values given in the "
                     "task ('measured'); their u comes from this task's points: see its notes for what those are")
    for r in results["characteristics"]:
        v = f"{r['value']:.6f} mm" if r["unit"] == "mm" else f"{r['value']:.4f} {r['unit']}"
        u_unit = "µm" if r["u_unit"] == "um" else "µrad"
        extra = f", zone {r['zone_mm']:.4f} mm" if r["zone_mm"] is not None else ""
        lines.append(f"{r['name']}: {v}, u = {r['u']:.3f} {u_unit}{extra}")
    return lines


# -- the records of the results (generator.quantities) -----------------------------------------

#: the drawing's tolerances are fields of the characteristics (no [[decision.tolerances]]); the
#: results give u only: U = k·u with the [decision] k (default 2)
TOLERANCE_KEYS = ToleranceKeys((), k_from_decision=True, note=(
    "the drawing's, on 'Characteristics': size and distance two-sided (lsl, usl, or nominal ± tolerance_mm); "
    "form, orientation, position one-sided (value <= tolerance_mm); a position at MMC/LMC on its margin = "
    "tolerance + bonus - value >= 0 (u with the size's); angles not decided yet"))
#: material conditions with a bonus tolerance: decided on the margin (zone - value >= 0)
BONUS_CONDITIONS = ("MMC", "LMC")
#: characteristic types with a two-sided tolerance interval (lsl/usl or nominal ± tolerance_mm)
TWO_SIDED_TYPES = ("diameter", "width", "distance", "cone_angle", "angle")
U_SOURCE = ("the point-cloud model V_X of six influence factors propagated to the characteristic through the "
            "joint fit of its features (Forbes 2022, 2025)")
#: columns of 'Characteristics' (generator.characteristic.book.CHAR_COLUMNS): value, u, nominal,
#: lsl, usl, tolerance_mm, margin_mm, u_margin_um
CHAR_SHEET = "Characteristics"
COL = {"value": 4, "u": 6, "nominal": 8, "lsl": 9, "usl": 10, "tolerance_mm": 11, "margin_mm": 15, "u_margin_um": 16}


def margin_label(name: str) -> str:
    """The decided quantity of a position at MMC/LMC: its margin (Characteristics, 'margin_mm')."""
    return f"{name} margin"


def tolerance(c: dict, row: int = 2) -> tuple[dict, str | None]:
    """The tolerance interval of one characteristic (a ``characteristics`` entry of the JSON) as
    the drawing gives it, and why it is not decided (None when it is).

    * size, distance (two-sided): ``lsl``/``usl`` (one of them: a one-sided interval), or
      ``nominal`` ± ``tolerance_mm``;
    * form, orientation, position RFS (a zone whose value is >= 0): one-sided, value <= USL =
      ``tolerance_mm`` (ISO 1101: the feature lies in a zone of that width);
    * position at MMC/LMC: decided on its margin (:func:`margin_label`);
    * angles (deg): not decided yet (the decision's fields are mm and µm).

    Returns ({"lsl": .., "usl": .., "cells": {"lsl_mm": formula, ...}}, reason); ``cells``: the
    limits as formulas of the row ``row`` of 'Characteristics', so that a tolerance typed there
    changes the decision."""
    typ = c["type"]
    lsl, usl, tol, nominal = c["lsl"], c["usl"], c["tolerance_mm"], c["nominal"]

    def at(name: str) -> str:
        return cell(row, COL[name], CHAR_SHEET)

    if lsl is None and usl is None and tol is None:
        return {}, None
    if c["unit"] != "mm":
        return {}, f"an angle tolerance ({c['unit']}) is not decided yet: the decision works in mm and µm"
    if typ in TWO_SIDED_TYPES:
        if lsl is not None or usl is not None:
            cells = {f"{k}_mm": at(k) for k, v in (("lsl", lsl), ("usl", usl)) if v is not None}
            if nominal is not None:
                cells["nominal"] = at("nominal")
            return {"lsl": lsl, "usl": usl, "cells": cells}, None
        if nominal is not None:
            return {"lsl": nominal - tol, "usl": nominal + tol,
                    "cells": {"lsl_mm": f"{at('nominal')}-{at('tolerance_mm')}",
                              "usl_mm": f"{at('nominal')}+{at('tolerance_mm')}", "nominal": at("nominal")}}, None
        return {}, "tolerance_mm of a size or distance needs its nominal (nominal ± tolerance_mm), or give lsl/usl"
    if tol is None:
        return {}, f"a {typ} takes tolerance_mm (a zone width), not lsl/usl"
    if typ == "position" and c["material_condition"] in BONUS_CONDITIONS:
        return {"margin": True}, None
    return {"lsl": None, "usl": tol, "cells": {"usl_mm": at("tolerance_mm")}}, None


def quantities(task: Task, results: dict, k: float = 2.0) -> list[Quantity]:
    """One record per characteristic (its Results row; a position at MMC/LMC also its margin,
    on 'Characteristics', right after it), with the drawing's tolerance, U = k·u with ``k`` (the
    ``[decision] k``, default 2).  Lengths: value mm, u µm; angles: value deg, u µrad, U in deg."""
    where = "the points table ([points] file)" if task.points_file else "the points given in the task file ([points] rows)"
    fitted = f"from the features fitted to {where}"
    out = []
    for i, c in enumerate(results["characteristics"]):
        r = i + 2
        deg = c["unit"] == "deg"
        tol, reason = tolerance(c, r)
        margin = tol.get("margin", False)
        lsl = tol.get("lsl")
        usl = tol.get("usl")
        q = Quantity(label=c["name"], value=c["value"], unit=c["unit"], u=c["u"], u_unit="µrad" if deg else "µm",
                     k=float(k), U_unit="deg" if deg else "µm", U_per_u=180 / math.pi * 1e-6 if deg else 1.0,
                     ident={"characteristic": c["name"]},
                     nominal=c["nominal"] if c["type"] in TWO_SIDED_TYPES else None, lsl=lsl, usl=usl,
                     value_source=fitted + (" (least squares)" if c["method"] != "MZ" else " (minimum zone)"),
                     u_source=U_SOURCE, own_U=False, not_decided=reason,
                     decided_as=margin_label(c["name"]) if margin else None,
                     cells=Cells(RESULTS, r, cell(r, 3, RESULTS), cell(r, 5, RESULTS), limits=tol.get("cells", {})))
        out.append(q)
        if margin and c["margin_mm"] is not None:
            label = margin_label(c["name"])
            out.append(Quantity(label=label, value=c["margin_mm"], unit="mm", u=c["u_margin_um"], u_unit="µm",
                                k=float(k), U_unit="µm", ident={"characteristic": label}, lsl=0.0,
                                value_source=(f"tolerance + bonus − position value of {c['name']} (ASME Y14.5-2018 "
                                              "5.8.1; the bonus from the measured size)"),
                                u_source=U_SOURCE + ", the size's uncertainty and its correlation with the position "
                                "included", own_U=False, quantity="margin_mm",
                                cells=Cells(CHAR_SHEET, r, cell(r, COL["margin_mm"], CHAR_SHEET),
                                            cell(r, COL["u_margin_um"], CHAR_SHEET), limits={"lsl_mm": "0"})))
    return out


def read_book(cells, rt, points_file: str) -> None:
    """The way back (``cmmwb read``): :func:`generator.characteristic.reader.read_characteristic`."""
    from .reader import read_characteristic

    read_characteristic(cells, rt, points_file)


NEW_TASK = '''# cmmwb characteristic task: characteristics of a drawing from least-squares features fitted
# in one task, with u under the six-factor point-cloud model (Forbes 2025).
# Units: coordinates mm, uncertainties µm in [parameters]; results: mm / deg, u in µm / µrad.
# Build with:  cmmwb build THIS.toml --out DIR

[task]
kind = "characteristic"
name = "my_part"

[points]
file = "points.csv"      # id,x,y,z,nx,ny,nz,probe  (nx..nz: outward unit normal)

[parameters]
sigma_R_um = 0.2
sigma_S_ppm = 0.7
sigma_PQ_um = 0.2
sigma_P0_um = 0.1

[[probes]]
id = "P1"
offset_mm = [0.0, 0.0, -50.0]

[[features]]              # a face: its points are those whose id starts with "A."
name = "A"
type = "plane"
id_prefix = "A."

[[features]]
name = "B"
type = "plane"
id_prefix = "B."

[[frames]]                # datum reference frame A|B (primary plane, secondary plane)
name = "AB"
primary = "A"
secondary = "B"

[[characteristics]]
name = "flatness_A"
type = "flatness"
features = ["A"]
method = "MZ"            # LS (peak-to-valley to the least-squares plane) or MZ (minimum zone)
tolerance_mm = 0.01

[[characteristics]]
name = "perpendicularity_B"
type = "perpendicularity"
features = ["B"]
frame = "AB"
tolerance_mm = 0.02

# Optional: the part's temperature, the factor W (docs/workpiece.md); without the table W is off.
# [workpiece]
# material = "aluminium"        # or alpha_ppm_per_K = 23.1 (1e-6/K); aluminium 23.1, steel 11.5
# u_alpha_ppm_per_K = 1.0       # u(alpha)
# T_degC = 23.5                 # the part's temperature, or T_readings_degC = [23.3, 23.7]
# u_T_K = 0.3                   # u(T) of the thermometer
# corrected = true              # the CMM corrects to 20 °C (with alpha_corr_ppm_per_K, default alpha)
# fixture_mm = [0, 0, 0]        # where the part is held (it expands about this point)
# enabled = true                # W on/off

# Every characteristic with a tolerance gets a conformity decision (sheet 'Decision'), by default
# under ISO 14253-1 with U = 2u. Uncomment the table below to choose (docs/conformity.md):
# [decision]
# rule = "iso14253"      # simple | iso14253 | guarded_acceptance | guarded_rejection | specific_risk
# k = 2.0                # U = k·u
#
# [report]               # shown on the 'Summary' sheet and in the JSON
# lab = "..."
# operator = "..."
'''

NEW_TASK_FILES = {"points.csv": '''# A face A (z = 0, outward normal -z) and a side face B (x = 0, outward -x), mm
id,x,y,z,nx,ny,nz,probe
A.1,10,10,0.0012,0,0,-1,P1
A.2,90,10,-0.0008,0,0,-1,P1
A.3,90,70,0.0021,0,0,-1,P1
A.4,10,70,-0.0015,0,0,-1,P1
A.5,50,40,0.0004,0,0,-1,P1
A.6,30,55,-0.0002,0,0,-1,P1
B.1,0.0011,10,3,-1,0,0,P1
B.2,-0.0006,70,3,-1,0,0,P1
B.3,0.0031,40,7,-1,0,0,P1
B.4,0.0019,20,7,-1,0,0,P1
'''}
