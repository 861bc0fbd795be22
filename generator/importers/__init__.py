"""``cmmwb import``: CMM result files in open formats -> cmmwb task files and recordings.

``qif``    QIF (ISO 23952) measured point sets -> a ``feature`` or ``pointcloud`` task (TOML +
           points CSV, the format of ``cmmwb new``/``build``); docs/import.md
``aqdef``  Q-DAS AQDEF (``.dfq``, ``.dfd`` + ``.dfx``) characteristic values -> what they can
           give: length recordings need point coordinates, which AQDEF does not carry

Every file is read through :func:`generator.workbook.guarded.read_bytes` (kind "import": a regular file, size cap).
"""

from __future__ import annotations

import csv
import io
import tomllib
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..workbook.atomic import replacing

QIF_SUFFIXES = (".qif", ".xml")
AQDEF_SUFFIXES = (".dfq", ".dfd", ".dfx")


def run_import(src: Path, out: Path, *, features: list[str] | None = None, kind: str | None = None,
               normals: str = "file", force: bool = False, stand_in: bool = False,
               part: str | None = None) -> tuple[list[Path], list[str]]:
    """Import ``src`` into ``out`` (``.toml``: a task with its points CSV beside it; ``.csv``:
    recordings; ``.qif``: a copy with the characteristics' u; ``stand_in``: the characteristics as
    a characteristic task of the simulated stand-in part, the values of ``part``).  Returns the
    files written and the report lines (what was read, converted, derived and left out)."""
    src, out = Path(src), Path(out)
    if (stand_in or part is not None) and src.suffix.lower() not in QIF_SUFFIXES:
        raise InputError("--stand-in and --part read a QIF file's characteristics", file=src)
    if part is not None and not stand_in:
        raise InputError("--part chooses the measured part of a --stand-in task; give --stand-in too",
                         where="--part")
    if stand_in:
        if features or kind:
            raise InputError("--stand-in writes every characteristic of the file on the stand-in part: leave "
                             "--feature and --kind out", where="--stand-in")
        from .qif_stand_in import write_stand_in_task
        return write_stand_in_task(src, out, part=part, force=force)
    suffix = src.suffix.lower()
    if suffix in AQDEF_SUFFIXES:
        from .aqdef import import_aqdef
        return import_aqdef(src, out, force=force)
    if suffix not in QIF_SUFFIXES:
        raise InputError(f"unknown file type {src.suffix!r}: cmmwb imports QIF (.qif) and Q-DAS AQDEF "
                         "(.dfq, .dfd + .dfx)", file=src)
    if out.suffix.lower() == ".qif":      # characteristics: a copy of the file with their u
        from .qif_simulation import annotate_file
        return annotate_file(src, out, force=force)
    from . import qif

    doc = qif.read_qif(src)
    report = [f"QIF {doc.version}: {len(doc.sets)} point sets, {len(doc.features)} features with points",
              f"length unit: {doc.unit_name}" + ("" if doc.mm_per_unit == 1.0 else f" -> mm (x {doc.mm_per_unit:g})"),
              "frame: the file's primary coordinate system (sets in other frames are refused)"]
    report += [f"not imported: {s}" for s in doc.not_read]
    if out.suffix.lower() == ".csv":
        files, lines = _write_recordings(doc, src, out, features, force)
        return files, report + lines
    if out.suffix.lower() != ".toml":
        raise InputError("--out must be a task file (.toml) or recordings (.csv)", file=out)
    if not features:
        listing = "; ".join(f"{f.name} ({f.kind.lower()}, {_count(doc, f)} points)" for f in doc.features)
        raise InputError(f"choose the feature(s) to import with --feature NAME; the file has: {listing}",
                         file=src)
    chosen = [doc.feature(k) for k in features]
    kind = kind or ("feature" if len(chosen) == 1 else "pointcloud")
    if kind == "feature" and len(chosen) != 1:
        raise InputError("a feature task fits one element: give one --feature", file=src)
    labels, X, N, notes = [], [], [], [f"imported by cmmwb import from {src.name} (QIF {doc.version})",
                                         _coordinates_note(doc.unit_name, doc.mm_per_unit)]
    for f in chosen:
        ps = doc.points_of(f)
        n = ps.N
        if n is None:
            if normals != "from-feature":
                raise InputError(f"the points of {f.name} have no normals in the file; the point-cloud "
                                 "model needs them (Forbes 2025 eq. (26)); give --normals from-feature to "
                                 "take them from the measured element (stated in the task notes)",
                                 file=src, where=ps.where)
            n, sentence = qif.normals_from_feature(doc, f, ps)
            notes.append(sentence)
        if ps.compensated is False:
            notes.append(f"{f.name}: Compensated = false, the coordinates are stylus-tip centres"
                         + (f" (probe radius {ps.probe_radius_mm:g} mm)" if ps.probe_radius_mm else ""))
        elif ps.compensated:
            notes.append(f"{f.name}: Compensated = true, surface points")
        labels += [f"{_label(f.name)}_{k + 1}" for k in range(len(ps.X_mm))]
        X.append(ps.X_mm)
        N.append(n)
    notes.append("[parameters] and the probe offset are placeholders (Forbes 2025 Table 3, MPE1; offset "
                 "0, 0, -50 mm): replace them with your machine's before trusting the uncertainties")
    X, N = np.vstack(X), np.vstack(N)
    feat = chosen[0]
    if kind == "feature" and feat.kind not in qif.ELEMENTS:
        raise InputError(f"{feat.name} is a {feat.kind.lower()} feature; a feature task fits one of "
                         f"{', '.join(qif.ELEMENTS.values())}", file=src)
    files = _write_task(out, kind, feat, X, N, labels, notes, force)
    return files, report + notes[1:]


def _write_recordings(doc, src: Path, out: Path, features: list[str] | None,
                      force: bool) -> tuple[list[Path], list[str]]:
    """Point recordings (docs/recordings.md 1b) of the chosen features (default: every feature
    with a nominal plane, circle, cylinder or sphere): measured points against their closest
    points on the nominal elements (:func:`qif.nominal_points`), one ``group`` per feature."""
    from . import qif

    if features:
        chosen = [doc.feature(k) for k in features]
    else:
        chosen = [f for f in doc.features if f.kind in qif.PROJECTABLE and f.nominal]
        if not chosen:
            raise InputError("no feature with a nominal plane, circle, cylinder or sphere to compute "
                             "nominal points on", file=src)
    lines = [f"nominal points: the closest points on the file's nominal elements "
             f"(FeatureNominal + the Diameter of its definition), {len(chosen)} features"]
    skipped = [f.name for f in doc.features if f not in chosen]
    if skipped and not features:
        lines.append("not imported as recordings (no nominal plane, circle, cylinder or sphere): "
                     + ", ".join(skipped))
    if out.exists() and not force:
        raise InputError("exists already (use --force to overwrite)", file=out)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    buf.write(f"# imported by cmmwb import from {_comment(src.name)} (QIF {doc.version}): "
              f"{_comment(_coordinates_note(doc.unit_name, doc.mm_per_unit))}\n"
              "# nominal points are the closest points on the nominal elements; nx ny nz their outward "
              "normals; group is the feature\n")
    w.writerow(["id", "x_nom", "y_nom", "z_nom", "x", "y", "z", "nx", "ny", "nz", "group"])
    for f in chosen:
        ps = doc.points_of(f)
        X_nom, N, sentence = qif.nominal_points(doc, f, ps)
        lines.append(sentence)
        for k, (xn, x, n) in enumerate(zip(X_nom, ps.X_mm, N)):
            w.writerow([f"{_label(f.name)}_{k + 1}", *(f"{v:.17g}" for v in xn), *(f"{v:.17g}" for v in x),
                        *(f"{v:.17g}" for v in n), _label(f.name)])
    with replacing(out) as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")
    return [out], lines


def _coordinates_note(unit_name: str, mm_per_unit: float) -> str:
    """What was done to the file's coordinates: nothing when they are in mm already."""
    if mm_per_unit == 1.0:
        return f"coordinates in mm, as in the file ({unit_name})"
    return f"coordinates converted from {unit_name} to mm (x {mm_per_unit:g})"


def _comment(text: str) -> str:
    """Text safe inside a one-line CSV comment."""
    return " ".join(text.replace(",", " ").split())


def _count(doc, f) -> int:
    try:
        return len(doc.points_of(f).X_mm)
    except InputError:
        return 0


def _label(name: str) -> str:
    keep = "".join(ch if ch.isalnum() or ch in "_-." else "_" for ch in name)
    return keep.lstrip("=+-@") or "F"


def _placeholders() -> tuple[dict, dict]:
    from ..feature.job import NEW_TASK

    doc = tomllib.loads(NEW_TASK)
    return doc["parameters"], doc["probes"][0]


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _write_task(out: Path, kind: str, f, X, N, labels, notes, force: bool) -> list[Path]:
    csv_path = out.with_suffix(".csv")
    for p in (out, csv_path):
        if p.exists() and not force:
            raise InputError("exists already (use --force to overwrite)", file=p)
    params, probe = _placeholders()
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["id", "x", "y", "z", "nx", "ny", "nz", "probe"])
    for lab, x, n in zip(labels, X, N):
        w.writerow([lab, *(f"{v:.17g}" for v in x), *(f"{v:.17g}" for v in n), probe["id"]])
    name = _label(out.stem)
    lines = ["# written by cmmwb import (docs/import.md)", "[task]", f"kind = {_toml_str(kind)}",
             f"name = {_toml_str(name)}", "notes = [", *(f"  {_toml_str(s)}," for s in notes), "]", ""]
    if kind == "feature":
        element = {"Line": "line", "Plane": "plane", "Circle": "circle", "Sphere": "sphere",
                   "Cylinder": "cylinder", "Cone": "cone"}[f.kind]
        lines += ["[feature]", f"type = {_toml_str(element)}"]
        axis = f.geometry.get("Normal", f.geometry.get("Direction"))
        if element == "circle":
            lines.append('circle_plane = "space"')
        if axis is not None and element in ("plane", "circle", "cylinder", "cone", "line"):
            lines.append("axis_hint = [" + ", ".join(f"{v:.17g}" for v in axis / np.linalg.norm(axis)) + "]")
        lines.append("")
    lines += ["[points]", f"file = {_toml_str(csv_path.name)}", "",
              "[parameters]                    # placeholders: replace with your machine's"]
    lines += [f"{k} = {v!r}" for k, v in params.items()]
    lines += ["", "[[probes]]", f"id = {_toml_str(probe['id'])}",
              "offset_mm = [" + ", ".join(f"{float(v)!r}" for v in probe["offset_mm"]) + "]   # placeholder", ""]
    with replacing(csv_path) as tmp_csv, replacing(out) as tmp_toml:
        tmp_csv.write_text(buf.getvalue(), encoding="utf-8")
        tmp_toml.write_text("\n".join(lines), encoding="utf-8")
    return [out, csv_path]
