"""``cmmwb import FILE.qif --stand-in --out TASK.toml [--part ID]``: a QIF file's characteristics
as a ``characteristic`` task that ``cmmwb build`` decides, with the stand-in part explicit.

A results file without points (NIST's SMS test bed files) carries each characteristic's kind,
nominal, tolerance and the measured values of every part, not the part's geometry.  The task
written here is the simulated stand-in part of :mod:`generator.importers.qif_simulation` (its
points CSV, features, the frame A|B|C, the MPE1-like point-cloud model) with one
``[[characteristics]]`` entry per measured value of the chosen part: its type and tolerance from
the file, its value from the file as ``measured`` (xlfuncs.characteristics: the value decided;
the stand-in's points give only the sensitivities and so u).  What comes from the stand-in part is
said in the task's notes (shown on the workbook's Instructions sheet and in the JSON), on every
measured value's cell note and in the report of the command; what cannot be decided is named:

* an item measured several times per part (a pattern of holes) gives one characteristic per
  measurement (``DIAMETER4 #1`` ... ``#4``), all on one stand-in feature;
* a position at MMC/LMC carries its bonus from the diameter measured on the same feature of the
  same part (``size``) and the feature's side (``InternalExternal``: a hole or a pin); without
  either it is written RFS without a tolerance (not decided) and the notes say why;
* a ``ToleranceValue`` that is not a zone (negative, or 0 regardless of feature size) is left
  out: not decided, said in the notes;
* characteristics the stand-in part does not simulate (widths, lengths, radii, profiles ...) and
  values the part lacks are named in the notes.
"""

from __future__ import annotations

import csv
import io
import json
import re
from dataclasses import replace
from pathlib import Path

from cmmwb.xlfuncs import characteristics as ch

from ..errors import InputError
from ..workbook.atomic import write_texts
from .qif_characteristics import Part, QifCharacteristics, read_characteristics
from .qif_simulation import PARAMS, PROBES, STAND_IN, simulate

#: the keys of a [[characteristics]] entry written, and the types they apply to (those the
#: characteristic kind reads: generator/characteristic/job.py APPLIES)
_FORM_ORIENT = ch.FORM_TYPES + ch.ORIENTATION_TYPES


def write_stand_in_task(src: Path, out: Path, *, part: str | None = None,
                        force: bool = False) -> tuple[list[Path], list[str]]:
    """Write the task ``out`` (and its points ``out`` with ``.csv``); returns the files and the
    report lines (module docstring)."""
    src, out = Path(src), Path(out)
    if out.suffix.lower() != ".toml":
        raise InputError("--stand-in writes a characteristic task: --out must end in .toml", file=out)
    csv_path = out.with_suffix(".csv")
    for p in (out, csv_path):
        if p.exists() and not force:
            raise InputError("exists already (use --force to overwrite)", file=p)
    doc = read_characteristics(src)
    chosen = _part(doc, part, src)
    X, N, feats, frames, specs, names, skipped = simulate(doc)
    spec_of = {s.name: s for s in specs}
    notes = [f"STAND-IN PART: the points of this task are a simulated measurement of a stand-in part built "
             f"from the nominals of {src.name} (QIF {doc.version}), not of the measured part; they give only "
             "the uncertainties: u " + STAND_IN,
             f"the values decided are the measured values of part {chosen.id} of {src.name} (given as "
             f"'measured', converted from {doc.length_unit}/{doc.angle_unit} to mm/deg): written by cmmwb import "
             "--stand-in (docs/import.md)",
             "[parameters] and [[probes]] are the stand-in's model (MPE1-like, Forbes 2025 Table 3): replace "
             "them with your machine's for your machine's u"]
    notes += [f"{name}: not in this task ({why})" for name, why in skipped]
    entries, name_of = [], {}
    taken: set[str] = set()
    counts = {it.id: sum(1 for a in chosen.actuals if a.item is it) for it in doc.items}
    # sizes first: a position at MMC names the size measured on its feature
    order = sorted(chosen.actuals, key=lambda a: a.item.definition.type != "diameter")
    for a in order:
        it = a.item
        if it.id not in names:
            continue
        k = [b for b in chosen.actuals if b.item is it].index(a) + 1
        name = _unique(it.name if counts[it.id] == 1 else f"{it.name} #{k}", it.id, taken)
        if a.value is None:
            notes.append(f"{name}: part {chosen.id} has no value for it: not in this task")
            continue
        spec = replace(spec_of[names[it.id]], name=name, measured=float(a.value))
        if it.definition.zone_problem:
            notes.append(f"{name}: {it.definition.zone_problem}: no tolerance written, not decided")
        if spec.type == "position" and it.definition.material_condition in ("MMC", "LMC"):
            size = doc.size_actual(chosen, a)
            why = doc.bonus_problem(it) or (None if size is not None and id(size) in name_of else
                                            f"part {chosen.id} has no diameter measured on the same feature")
            if why:
                spec = replace(spec, material_condition="RFS", size=None, tolerance_mm=None)
                notes.append(f"{name}: {why}: written RFS without its tolerance, not decided (a decision at RFS "
                             "would ignore the bonus)")
            else:
                spec = replace(spec, size=name_of[id(size)])
                notes.append(f"{name}: at {it.definition.material_condition}, bonus from {name_of[id(size)]} "
                             f"({'a hole' if it.internal else 'a pin'}, InternalExternal of its feature)")
        name_of[id(a)] = name
        entries.append(spec)
    if not entries:
        raise InputError(f"part {chosen.id} has no characteristic the stand-in part simulates", file=src)
    by_file_order = {id(a): n for n, a in enumerate(chosen.actuals)}
    actual_of = {v: k for k, v in name_of.items()}
    entries.sort(key=lambda s: by_file_order[actual_of[s.name]])
    labels = _labels(feats, len(X))
    task_name = _file_name(out.stem)
    files = {out: _toml(task_name, notes, csv_path.name, feats, frames, entries, labels),
             csv_path: _points_csv(X, N, labels)}
    write_texts({csv_path: files[csv_path], out: files[out]})
    report = [f"QIF {doc.version}: {len(doc.items)} characteristics, {len(doc.parts)} measured part(s) "
              f"({', '.join(p.id for p in doc.parts[:8])}{' ...' if len(doc.parts) > 8 else ''}); "
              f"units: {doc.units}",
              f"part {chosen.id}: {len(entries)} measured values -> [[characteristics]] with 'measured'",
              f"stand-in part: {len(X)} simulated points of {len(feats)} features (u {STAND_IN})",
              *notes[3:]]
    return [out, csv_path], report


def _part(doc: QifCharacteristics, part: str | None, src: Path) -> Part:
    if not doc.parts:
        raise InputError("no measured part (MeasurementResults): no values to decide", file=src)
    if part is None:
        return doc.parts[0]
    for p in doc.parts:
        if p.id == part:
            return p
    raise InputError(f"no part {part!r}; the file's parts (MeasurementResults ids): "
                     f"{', '.join(p.id for p in doc.parts)}", file=src, where="--part")


_UNSAFE = re.compile(r"[\x00-\x1f\x7f]")


def _unique(name: str, item_id: str, taken: set[str]) -> str:
    """A characteristic name of the task: the file's, without control characters, at most 100
    characters, and another than every name before (the item's id added)."""
    name = _UNSAFE.sub(" ", name).strip()[:80] or f"item {item_id}"
    if name in taken or name.endswith(" margin"):
        name = f"{name} (item {item_id})"
    taken.add(name)
    return name


def _file_name(stem: str) -> str:
    keep = "".join(c if c.isalnum() or c in "_-." else "_" for c in stem).strip(".")
    return keep or "stand_in"


def _labels(feats: list[ch.FeatureSpec], m: int) -> list[str]:
    """Point ids: the feature's name and the point's number (``H23.4``); features' points are
    contiguous blocks of the stand-in (qif_simulation._Builder)."""
    labels = [""] * m
    for f in feats:
        for k, i in enumerate(f.indices, start=1):
            labels[i] = f"{f.name}.{k}"
    return labels


def _points_csv(X, N, labels) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["id", "x", "y", "z", "nx", "ny", "nz", "probe"])
    for lab, x, n in zip(labels, X, N):
        w.writerow([lab, *(f"{v:.12g}" for v in x), *(f"{v:.12g}" for v in n), PROBES[0].id])
    return "# the stand-in part of cmmwb import --stand-in (simulated, not measured; mm)\n" + buf.getvalue()


def _s(text: str) -> str:
    """A TOML basic string (JSON's escapes are TOML's)."""
    return json.dumps(text, ensure_ascii=False)


def _num(v: float) -> str:
    return repr(float(v))


def _toml(name: str, notes: list[str], points: str, feats, frames, chars, labels) -> str:
    out = ["# written by cmmwb import --stand-in (docs/import.md): the characteristics of a QIF results file",
           "# on a SIMULATED STAND-IN PART; the values are the file's, the uncertainties the stand-in's",
           "[task]", 'kind = "characteristic"', f"name = {_s(name)}", "notes = ["]
    out += [f"  {_s(n)}," for n in notes] + ["]", "", "[points]", f"file = {_s(points)}", "", "[parameters]"]
    out += [f"{k} = {_num(getattr(PARAMS, k))}" for k in PARAMS.__dataclass_fields__ if getattr(PARAMS, k)]
    for p in PROBES:
        out += ["", "[[probes]]", f"id = {_s(p.id)}", "offset_mm = [" + ", ".join(_num(v) for v in p.offset_mm) + "]"]
    for f in feats:
        out += ["", "[[features]]", f"name = {_s(f.name)}", f"type = {_s(f.element)}", f"id_prefix = {_s(f.name + '.')}"]
        if f.element == "circle":
            out.append(f"circle_plane = {_s(f.circle_plane or 'space')}")
        if f.axis_hint is not None:
            out.append("axis_hint = [" + ", ".join(_num(v) for v in f.axis_hint) + "]")
    for fr in frames:
        out += ["", "[[frames]]", f"name = {_s(fr.name)}", f"primary = {_s(fr.primary)}"]
        out += [f"{k} = {_s(getattr(fr, k))}" for k in ("secondary", "tertiary") if getattr(fr, k)]
    for c in chars:
        out += ["", "[[characteristics]]", f"name = {_s(c.name)}", f"type = {_s(c.type)}",
                "features = [" + ", ".join(_s(f) for f in c.features) + "]"]
        if c.type in _FORM_ORIENT:
            out.append(f"method = {_s(c.method)}")
        if c.frame is not None:
            out.append(f"frame = {_s(c.frame)}")
        if c.type in ch.ORIENTATION_TYPES + ("position",) and c.zone != "planar":
            out.append(f"zone = {_s(c.zone)}")
        if c.nominal_position_mm is not None:
            out.append("nominal_position_mm = [" + ", ".join(_num(v) for v in c.nominal_position_mm) + "]")
        if c.type == "position" and c.material_condition != "RFS":
            out += [f"material_condition = {_s(c.material_condition)}", f"size = {_s(c.size)}",
                    f"internal = {'true' if c.internal else 'false'}"]
        for key in ("nominal", "lsl", "usl", "tolerance_mm"):
            v = getattr(c, key)
            if v is not None and not (key == "nominal" and c.type in ch.FORM_TYPES + ("position",)):
                out.append(f"{key} = {_num(v)}")
        out.append(f"measured = {_num(c.measured)}          # the file's value; u from the stand-in part")
    return "\n".join(out) + "\n"
