"""QIF (ISO 23952, Quality Information Framework) measured point sets.

A schema-driven reader of the parts of a QIF document that cmmwb uses (element names of the
QIF 3.0 schema ``Features.xsd``/``Primitives.xsd``; QIF 2.x ``MeasurePoint`` lists too):

``FileUnits/PrimaryUnits/LinearUnit``   ``UnitName`` and ``UnitConversion/Factor`` (to metres):
                                        every coordinate is converted to mm with it
``MeasuredPointSet`` (QIF 3)            ``Points`` (x y z ...), ``Normals`` (i j k ...),
                                        ``Compensated``, ``ProbeRadius``, per-set ``Units``
``PointList/MeasurePoint`` (QIF 2)      ``Point``, ``Normal``, ``Compensated``, ``ProbeRadius``
``<Kind>FeatureMeasurement``/``Actual`` the feature the points belong to (``PointList`` of
                                        ``WholePointSetId``/``RangePointSetId``), its measured
                                        geometry, and through ``FeatureItemId`` its name
                                        (``FeatureName``) and nominal (``InternalExternal``)

Everything else that would change the meaning of the points is named in an error
(``BinaryPoints``, a ``CoordinateSystemId``/``TranformId`` frame, ``SinglePointSetId``
subsets); the rest of the document (plans, characteristics, statistics) is not read and the
report says so.  XML is parsed with ``defusedxml`` (no DTDs, no entity expansion).

Normals: when the file gives none, a feature task can take them from the measured element
(``normals = "from-feature"``): plane normal, radial directions of circles, cylinders and
spheres, with the sign of ``InternalExternal`` -- stated in the task notes.  Nothing is
invented silently.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from defusedxml import ElementTree as DET

from ..errors import InputError
from ..workbook.guarded import read_bytes

#: QIF feature kinds that are cmmwb elements (xlfuncs.features.ELEMENTS)
ELEMENTS = {"Line": "line", "Plane": "plane", "Circle": "circle", "Sphere": "sphere",
            "Cylinder": "cylinder", "Cone": "cone"}


@dataclass
class PointSet:
    id: str
    X_mm: np.ndarray                 # (n, 3)
    N: np.ndarray | None             # (n, 3) unit normals, or None
    compensated: bool | None         # True: surface points; False: stylus-tip centres
    probe_radius_mm: float | None
    where: str


@dataclass
class Feature:
    kind: str                        # QIF kind: Plane, Circle, ...
    id: str                          # id of the FeatureMeasurement / FeatureActual
    name: str                        # FeatureName of its FeatureItem (or the id)
    set_ids: list[tuple[str, tuple[int, int] | None]]
    geometry: dict                   # measured geometry in mm (Location, Normal, Axis, ...)
    internal: bool | None            # InternalExternal of the nominal: True INTERNAL
    nominal_id: str | None = None    # id of its FeatureNominal
    nominal: dict = field(default_factory=dict)  # nominal geometry in mm (Location, Normal, Axis, Diameter)


@dataclass
class QifDocument:
    path: Path
    version: str
    unit_name: str
    mm_per_unit: float
    sets: dict[str, PointSet] = field(default_factory=dict)
    features: list[Feature] = field(default_factory=list)
    not_read: list[str] = field(default_factory=list)
    #: features in the file whose points cmmwb cannot import: (name, QIF kind, id, why)
    unsupported: list[tuple[str, str, str, str]] = field(default_factory=list)
    #: every FeatureItem (a feature of the part, measured or not): name -> (QIF kind, id)
    items: dict[str, tuple[str, str]] = field(default_factory=dict)

    def feature(self, key: str) -> Feature:
        for f in self.features:
            if key in (f.name, f.id):
                return f
        for name, kind, fid, why in self.unsupported:
            if key in (name, fid):
                raise InputError(f"feature {name} is in the file (a {kind.lower()} feature, id {fid}) but not "
                                 f"supported: {why}", file=self.path, where="--feature")
        if key in self.items:
            kind, iid = self.items[key]
            raise InputError(f"feature {key} is in the file (a {kind.lower()} feature item, id {iid}) but has no "
                             "measurement (no FeatureMeasurement or FeatureActual refers to it): no points to "
                             "import", file=self.path, where="--feature")
        names = ", ".join(f"{f.name} ({f.kind.lower()}, id {f.id})" for f in self.features) or "none"
        other = "; not importable: " + ", ".join(f"{n} ({k.lower()})" for n, k, _, _ in self.unsupported) \
            if self.unsupported else ""
        raise InputError(f"no feature named or numbered {key!r}; the file has: {names}{other}",
                         file=self.path, where="--feature")

    def points_of(self, f: Feature) -> PointSet:
        """The points of one feature, joined from its point sets (ranges are 1-based, inclusive)."""
        parts = []
        for sid, rng in f.set_ids:
            if sid not in self.sets:
                raise InputError(f"feature {f.name} refers to point set {sid}, which the file does not "
                                 "hold", file=self.path, where=f"{f.kind}Feature id={f.id}")
            s = self.sets[sid]
            if rng is not None and rng[1] > len(s.X_mm):
                raise InputError(f"feature {f.name} takes points {rng[0]}-{rng[1]} of point set {sid}, which "
                                 f"holds {len(s.X_mm)}", file=self.path, where=f"{f.kind}Feature id={f.id}")
            sl = slice(None) if rng is None else slice(rng[0] - 1, rng[1])
            parts.append((s, sl))
        X = np.vstack([s.X_mm[sl] for s, sl in parts])
        N = None if any(s.N is None for s, _ in parts) else np.vstack([s.N[sl] for s, sl in parts])
        comp = {s.compensated for s, _ in parts}
        radii = {s.probe_radius_mm for s, _ in parts}
        return PointSet(",".join(s.id for s, _ in parts), X, N, comp.pop() if len(comp) == 1 else None,
                        radii.pop() if len(radii) == 1 else None, parts[0][0].where)


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _child(el, name: str):
    for c in el:
        if _local(c.tag) == name:
            return c
    return None


def _children(el, name: str):
    return [c for c in el if _local(c.tag) == name]


def unique_ids(path: Path, root) -> None:
    """Every ``id`` of a QIF document names one element (the QIF 3 schema's ``QIFIdUnique`` over
    all elements): an id given twice is refused naming both elements, because every reference to
    it (a feature's point set, a characteristic's feature, a measured value's item, ``--part``)
    would silently reach one of them."""
    first: dict[str, str] = {}
    for el in root.iter():
        i = el.get("id")
        if i is None or not isinstance(el.tag, str):
            continue
        here = f"{_local(el.tag)} id={i}"
        if i in first:
            raise InputError(f"id {i} is used twice (also {first[i]}, the first): QIF ids name one element "
                             "each, and a reference to this one would reach either", file=path,
                             where=f"{here} (the second)")
        first[i] = here


def _numbers(path: Path, text: str | None, where: str) -> np.ndarray:
    try:
        v = np.array([float(t) for t in (text or "").split()], dtype=float)
    except ValueError as e:
        raise InputError(f"not a list of numbers ({e})", file=path, where=where) from None
    if not np.all(np.isfinite(v)):
        raise InputError("contains a non-finite number", file=path, where=where)
    return v


#: unit names understood without a ``UnitConversion`` (QIF's defaults are mm and degrees): length
#: units in mm, angle units in degrees
LENGTH_UNITS = {"mm": 1.0, "millimeter": 1.0, "millimetre": 1.0, "millimeters": 1.0, "millimetres": 1.0,
                "m": 1000.0, "meter": 1000.0, "metre": 1000.0, "meters": 1000.0, "metres": 1000.0,
                "cm": 10.0, "centimeter": 10.0, "centimetre": 10.0, "um": 1e-3, "micrometer": 1e-3,
                "micrometre": 1e-3, "micron": 1e-3, "inch": 25.4, "inches": 25.4, "in": 25.4,
                "ft": 304.8, "foot": 304.8, "feet": 304.8}
ANGLE_UNITS = {"deg": 1.0, "degree": 1.0, "degrees": 1.0, "rad": 180.0 / np.pi, "radian": 180.0 / np.pi,
               "radians": 180.0 / np.pi}


def _unit_conversion(path: Path, el, where: str, known: dict, si_scale: float, what: str) -> tuple[str, float] | None:
    """(UnitName, cmmwb units per file unit) of a ``LinearUnit``/``AngularUnit`` element, or None.
    ``UnitConversion/Factor`` converts to the SI unit (metre, radian) and ``si_scale`` turns that
    into mm or degrees; without it the name must be one of ``known``.  A Factor that is not one
    positive number, or an Offset, is an error naming the element."""
    if el is None:
        return None
    name_el = _child(el, "UnitName")
    name = (name_el.text or "").strip() if name_el is not None else "?"
    conv = _child(el, "UnitConversion")
    if conv is None or _child(conv, "Factor") is None:
        if name.lower() not in known:
            raise InputError(f"{what} unit {name!r} without UnitConversion/Factor (known without one: "
                             f"{', '.join(sorted(known))})", file=path, where=where)
        return name, known[name.lower()]
    factor = _numbers(path, _child(conv, "Factor").text, f"{where}/UnitConversion/Factor")
    offset = _child(conv, "Offset")
    if offset is not None and np.any(_numbers(path, offset.text or "0", f"{where}/UnitConversion/Offset") != 0):
        raise InputError(f"a {what} unit with an offset is not supported", file=path, where=where)
    if factor.size != 1 or factor[0] <= 0:
        raise InputError("UnitConversion/Factor must be one positive number", file=path,
                         where=f"{where}/UnitConversion/Factor")
    out = float(factor[0]) * si_scale
    if name.lower() in known and not np.isclose(out, known[name.lower()], rtol=1e-6):
        raise InputError(f"UnitName {name!r} but UnitConversion/Factor {factor[0]:g} (a {name} is "
                         f"{known[name.lower()] / si_scale:g}): which is it?", file=path,
                         where=f"{where}/UnitConversion/Factor")
    return name, out


def _linear_unit(path: Path, el, where: str) -> tuple[str, float] | None:
    """(UnitName, mm per unit) of a ``LinearUnit`` element, or None."""
    return _unit_conversion(path, el, where, LENGTH_UNITS, 1000.0, "length")


@dataclass(frozen=True)
class FileUnits:
    """The units of a QIF document's values (``FileUnits/PrimaryUnits``), the one reader of them
    for points and characteristics: mm per file length unit, degrees per file angle unit."""

    length_name: str
    mm_per_unit: float
    angle_name: str
    deg_per_unit: float
    stated: bool                      # the file has FileUnits/PrimaryUnits

    @property
    def text(self) -> str:
        if not self.stated:
            return "no FileUnits in the file: lengths read as mm, angles as degrees (QIF's defaults)"
        return (f"lengths in {self.length_name} (x {self.mm_per_unit:g} -> mm), angles in {self.angle_name} "
                f"(x {self.deg_per_unit:g} -> deg)")


def file_units(path: Path, root) -> FileUnits:
    """The :class:`FileUnits` of the document ``root`` (QIF defaults: mm, degrees)."""
    fu = _child(root, "FileUnits")
    pu = None if fu is None else _child(fu, "PrimaryUnits")
    where = "FileUnits/PrimaryUnits"
    lin = None if pu is None else _linear_unit(path, _child(pu, "LinearUnit"), f"{where}/LinearUnit")
    ang = None if pu is None else _unit_conversion(path, _child(pu, "AngularUnit"), f"{where}/AngularUnit",
                                                   ANGLE_UNITS, 180.0 / np.pi, "angle")
    return FileUnits(lin[0] if lin else "mm", lin[1] if lin else 1.0, ang[0] if ang else "degree",
                     ang[1] if ang else 1.0, pu is not None)


def read_qif(path: str | Path) -> QifDocument:
    """Parse a QIF document (guarded read, defusedxml)."""
    path = Path(path)
    raw = read_bytes(path, "import")
    try:
        root = DET.fromstring(raw, forbid_dtd=True)
    except DET.ParseError as e:
        raise InputError(f"not well-formed XML: {e}", file=path) from None
    except Exception as e:  # defusedxml: DTD, entities, external references
        raise InputError(f"refused: {type(e).__name__} (QIF files need no DTD or entities)", file=path) from None
    if _local(root.tag) != "QIFDocument":
        raise InputError(f"root element is {_local(root.tag)!r}, not QIFDocument", file=path)
    version = root.get("versionQIF", "?")

    units = file_units(path, root)
    fu = _child(root, "FileUnits")
    has_linear = fu is not None and _child(fu, "PrimaryUnits") is not None and \
        _child(_child(fu, "PrimaryUnits"), "LinearUnit") is not None
    unit_name = units.length_name if has_linear else "mm (QIF default: no FileUnits/PrimaryUnits/LinearUnit)"
    mm = units.mm_per_unit
    doc = QifDocument(path, version, unit_name, mm)

    # names and nominals of the feature items
    items: dict[str, tuple[str, str | None]] = {}
    nominal_def: dict[str, str] = {}
    definitions: dict[str, bool | None] = {}
    diameters: dict[str, float] = {}
    nominal_geometry: dict[str, dict] = {}
    for el in root.iter():
        tag = _local(el.tag)
        if tag.endswith("FeatureDefinition") and el.get("id"):
            ie = _child(el, "InternalExternal")
            definitions[el.get("id")] = None if ie is None else {"INTERNAL": True, "EXTERNAL": False}.get(
                (ie.text or "").strip())
            dia = _child(el, "Diameter")
            if dia is not None:
                d = _numbers(path, dia.text, f"{tag} id={el.get('id')}/Diameter")
                if d.size != 1 or d[0] <= 0:
                    raise InputError("Diameter must be one positive number", file=path,
                                     where=f"{tag} id={el.get('id')}")
                diameters[el.get("id")] = float(d[0]) * mm
        elif tag.endswith("FeatureNominal") and el.get("id"):
            d = _child(el, "FeatureDefinitionId")
            if d is not None:
                nominal_def[el.get("id")] = (d.text or "").strip()
            nominal_geometry[el.get("id")] = _geometry(path, el, f"{tag} id={el.get('id')}", mm)
        elif tag.endswith("FeatureItem") and el.get("id"):
            name = _child(el, "FeatureName")
            nom = _child(el, "FeatureNominalId")
            items[el.get("id")] = ((name.text or "").strip() if name is not None else el.get("id"),
                                   None if nom is None else (nom.text or "").strip())
            doc.items[items[el.get("id")][0]] = (tag.removesuffix("FeatureItem"), el.get("id"))

    # point sets (QIF 3) and point lists (QIF 2)
    for el in root.iter():
        tag = _local(el.tag)
        if tag == "MeasuredPointSet":
            _read_set(doc, el)
        elif (tag.endswith("FeatureMeasurement") or tag.endswith("FeatureActual")) and el.get("id"):
            _read_feature(doc, el, tag, items, nominal_def, definitions)
    for f in doc.features:  # the nominal element of each measured feature, with its diameter
        if f.nominal_id in nominal_geometry:
            f.nominal = dict(nominal_geometry[f.nominal_id])
            dia = diameters.get(nominal_def.get(f.nominal_id, ""))
            if dia is not None:
                f.nominal["Diameter"] = dia
    unique_ids(path, root)      # after the point sets, whose own message says what a twice-used id breaks
    if not doc.sets:
        other = ("; its characteristics: --out COPY.qif writes a copy with their uncertainties, --stand-in "
                 "--out TASK.toml a characteristic task on a simulated stand-in part that cmmwb build decides "
                 "(docs/import.md)") if _child(root, "Characteristics") is not None else ""
        raise InputError("no measured points (no MeasuredPointSet and no PointList/MeasurePoint): "
                         "cmmwb imports measured point sets; this file holds "
                         + (", ".join(sorted({_local(c.tag) for c in root})) or "nothing") + other, file=path)
    doc.not_read.append("plans, characteristics and statistics are not read (cmmwb needs the points and "
                        "the nominal elements)")
    return doc


def _read_set(doc: QifDocument, el) -> None:
    path, sid = doc.path, el.get("id", "?")
    where = f"MeasuredPointSet id={sid}"
    for unsupported in ("BinaryPoints", "BinaryNormals", "CoordinateSystemId", "TranformId"):
        if _child(el, unsupported) is not None:
            what = {"BinaryPoints": "binary point lists", "BinaryNormals": "binary normal lists",
                    "CoordinateSystemId": "points in another coordinate system",
                    "TranformId": "points under a transform"}[unsupported]
            raise InputError(f"{unsupported}: {what} are not supported by this importer "
                             "(export the points as decimal Points in the file's primary frame)",
                             file=path, where=where)
    mm = doc.mm_per_unit
    units = _child(el, "Units")
    if units is not None:
        lu = _linear_unit(path, _child(units, "LinearUnit"), f"{where}/Units/LinearUnit")
        if lu:
            mm = lu[1]
    pts = _child(el, "Points")
    if pts is None:
        raise InputError("no Points", file=path, where=where)
    P = _numbers(path, pts.text, f"{where}/Points")
    try:
        count = int(el.get("count", P.size // 3))
    except ValueError:
        raise InputError(f"count = {el.get('count')!r} is not a whole number", file=path, where=where) from None
    if P.size != 3 * count:
        raise InputError(f"count = {count} but Points holds {P.size} numbers (expected {3 * count})",
                         file=path, where=where)
    N = None
    nel = _child(el, "Normals")
    if nel is not None:
        N = _numbers(path, nel.text, f"{where}/Normals").reshape(-1, 3)
        if N.shape[0] != count:
            raise InputError(f"{N.shape[0]} normals for {count} points", file=path, where=where)
        N = _unit(path, N, where)
    comp = _child(el, "Compensated")
    radius = _child(el, "ProbeRadius")
    if sid in doc.sets:
        raise InputError(f"point set id {sid} is used twice (also {doc.sets[sid].where}, the first): a feature "
                         "referring to it would get the other's points", file=path, where=f"{where} (the second)")
    doc.sets[sid] = PointSet(sid, P.reshape(-1, 3) * mm, N,
                             None if comp is None else (comp.text or "").strip() == "true",
                             None if radius is None else _radius(path, radius, where) * mm, where)


#: a unit vector of the file (point normal, direction of a feature) may differ from length 1 by this
UNIT_TOL = 1e-3


def _radius(path: Path, el, where: str) -> float:
    """A ``ProbeRadius``: one non-negative number (in the file's unit)."""
    r = _numbers(path, el.text, f"{where}/ProbeRadius")
    if r.size != 1 or r[0] < 0:
        raise InputError("ProbeRadius must be one non-negative number", file=path, where=where)
    return float(r[0])


def _range(path: Path, text: str, where: str) -> tuple[int, int]:
    """The ``range="first last"`` of a RangePointSetId: two whole numbers, 1 <= first <= last."""
    parts = text.split()
    try:
        lo, hi = (int(x) for x in parts)
    except ValueError:
        raise InputError(f"range {text!r} is not two whole numbers 'first last'", file=path, where=where) from None
    if not 1 <= lo <= hi:
        raise InputError(f"range {text!r}: expected 1 <= first <= last", file=path, where=where)
    return lo, hi


def _unit(path: Path, N: np.ndarray, where: str) -> np.ndarray:
    norm = np.linalg.norm(N, axis=1)
    if np.any(np.abs(norm - 1) > UNIT_TOL):
        k = int(np.argmax(np.abs(norm - 1)))
        raise InputError(f"normal {k + 1} has length {norm[k]:.6g}, not 1", file=path, where=where)
    return N / norm[:, None]


def _vec(path, el, name, where, mm: float = 1.0):
    c = _child(el, name)
    if c is None:
        return None
    v = _numbers(path, c.text, f"{where}/{name}")
    if v.size != 3:
        raise InputError(f"{name}: expected 3 numbers", file=path, where=where)
    return v * mm


def _read_feature(doc: QifDocument, el, tag: str, items, nominal_def, definitions) -> None:
    path, fid = doc.path, el.get("id")
    kind = tag.replace("FeatureMeasurement", "").replace("FeatureActual", "")
    where = f"{tag} id={fid}"
    item = _child(el, "FeatureItemId")
    name, nominal = items.get((item.text or "").strip(), (fid, None)) if item is not None else (fid, None)
    internal = definitions.get(nominal_def.get(nominal or "", ""))
    set_ids: list[tuple[str, tuple[int, int] | None]] = []
    plist = _child(el, "PointList")
    if plist is not None:
        mps = _children(plist, "MeasurePoint")
        if mps:  # QIF 2: the points are inside the feature
            X, N = [], []
            for k, mp in enumerate(mps):
                X.append(_vec(path, mp, "Point", f"{where}/MeasurePoint[{k + 1}]"))
                N.append(_vec(path, mp, "Normal", f"{where}/MeasurePoint[{k + 1}]"))
            if any(x is None for x in X):
                raise InputError("a MeasurePoint without Point", file=path, where=where)
            comp = _child(mps[0], "Compensated")
            radius = _child(mps[0], "ProbeRadius")
            sid = f"feature{fid}"
            if sid in doc.sets:
                raise InputError(f"feature id {fid} is used twice (also {doc.sets[sid].where}, the first): its "
                                 "points would be the other's", file=path, where=f"{where} (the second)")
            normals = None if any(n is None for n in N) else _unit(path, np.array(N), where)
            doc.sets[sid] = PointSet(sid, np.array(X) * doc.mm_per_unit, normals,
                                     None if comp is None else (comp.text or "").strip() == "true",
                                     None if radius is None else _radius(path, radius, where) * doc.mm_per_unit,
                                     where)
            set_ids.append((sid, None))
        for ref in plist:
            rt = _local(ref.tag)
            if rt == "WholePointSetId":
                set_ids.append(((ref.text or "").strip(), None))
            elif rt == "RangePointSetId":
                lo, hi = _range(path, ref.get("range", ""), f"{where}/RangePointSetId")
                set_ids.append(((ref.text or "").strip(), (lo, hi)))
            elif rt == "SinglePointSetId":
                why = ("its points are single points of other point sets (SinglePointSetId): constructed "
                       "from other features' points, not imported")
                doc.not_read.append(f"{where} ({name}): {why}")
                doc.unsupported.append((name, kind, fid, why))
                set_ids = []
                break
    geometry = _geometry(path, el, where, doc.mm_per_unit)
    if set_ids:
        feature = Feature(kind, fid, name, set_ids, geometry, internal)
        feature.nominal_id = nominal
        doc.features.append(feature)
    elif plist is None:      # e.g. a point given by its Location only (POINT3 of a CMM report)
        given = ", ".join(k for k in ("Location", "Normal", "Direction", "AxisPoint") if k in geometry)
        why = (f"measured without a point list (no PointList; the file gives only its {given or 'result'}): "
               "no points to import")
        doc.not_read.append(f"{where} ({name}): {why}")
        doc.unsupported.append((name, kind, fid, why))


def _geometry(path: Path, el, where: str, mm: float) -> dict:
    """Location, Normal, Direction and Axis (AxisPoint, Direction) of a feature element, in mm."""
    geometry = {}
    for key in ("Location", "Normal", "Direction"):
        v = _vec(path, el, key, where, mm if key == "Location" else 1.0)
        if v is not None:
            geometry[key] = v
    axis = _child(el, "Axis")
    if axis is not None:
        geometry["AxisPoint"] = _vec(path, axis, "AxisPoint", where, mm)
        geometry["Direction"] = _vec(path, axis, "Direction", where)
    for key in ("Normal", "Direction"):
        if key in geometry and geometry[key] is not None:
            v = geometry[key]
            norm = float(np.linalg.norm(v))
            if not norm > 0:
                raise InputError(f"{key} is the zero vector", file=path, where=where)
            if abs(norm - 1.0) > UNIT_TOL:
                # normalising it would hide a defect (Location and Normal swapped: the points'
                # nominal positions would move by millimetres), as for the point normals
                point = "Location" if "Location" in geometry else "AxisPoint"
                loc = geometry.get(point)
                swapped = (f" (are {point} and {key} swapped? the {point} has length "
                           f"{float(np.linalg.norm(loc / mm)):.6g})"
                           if loc is not None and abs(float(np.linalg.norm(loc / mm)) - 1.0) <= UNIT_TOL else "")
                raise InputError(f"{key} ({v[0]:g}, {v[1]:g}, {v[2]:g}) has length {norm:.6g}, not 1: a direction "
                                 f"must be a unit vector{swapped}", file=path, where=where)
            geometry[key] = v / norm
    return geometry


def normals_from_feature(doc: QifDocument, f: Feature, ps: PointSet) -> tuple[np.ndarray, str]:
    """Outward unit normals of the points from the measured element, and the sentence that
    says so.  INTERNAL features (holes) point towards the axis/centre; where the file does not
    say, the side comes from the tip-centre radii against the nominal diameter (:func:`_side`),
    else the feature is taken as EXTERNAL and the sentence says so."""
    g, where, X = f.geometry, f"{f.kind}Feature id={f.id} ({f.name})", ps.X_mm
    if f.kind == "Plane" and "Normal" in g:
        N = np.tile(g["Normal"] / np.linalg.norm(g["Normal"]), (len(X), 1))
        return N, f"normals = the measured plane normal of {where} (the file gives no point normals)"
    if f.kind in ("Circle", "Cylinder", "Cone", "Sphere"):
        c = g.get("Location", g.get("AxisPoint"))
        a = None if f.kind == "Sphere" else g.get("Normal", g.get("Direction"))
        if c is not None and (a is not None or f.kind == "Sphere"):
            _, dist, u = _radial(X, c, a)
            if np.any(dist < 1e-9 * max(float(np.max(dist)), 1.0)):
                raise InputError(f"a point of {f.name} lies on the measured axis/centre: its radial "
                                 "normal is undefined", file=doc.path, where=ps.where)
            diameter = f.nominal.get("Diameter") if f.kind != "Cone" else None
            offset = ps.probe_radius_mm if ps.compensated is False and ps.probe_radius_mm else 0.0
            internal, side = _side(f, None, dist, u, None if diameter is None else diameter / 2, offset)
            if internal is None:
                internal, side = False, "InternalExternal not given: taken as EXTERNAL"
            side += ": towards the axis" if internal else ": away from the axis"
            centre = "centre" if f.kind == "Sphere" else "axis"
            return (-u if internal else u), (f"normals = radial directions from the measured {centre} of "
                                             f"{where} ({side}); the file gives no point normals")
    raise InputError(f"the file gives no normals for the points of {f.name}, and a {f.kind.lower()} "
                     "gives none from its geometry; the point-cloud model needs the outward normal of "
                     "every point (Forbes 2025 eq. (26))", file=doc.path, where=where)


def _radial(X: np.ndarray, centre: np.ndarray, axis: np.ndarray | None):
    """(along, dist, u) of points X about an axis through ``centre`` with unit direction ``axis``
    (None: about the point ``centre``, a sphere): the axial part of X - centre, the radial
    distances and the unit radial directions."""
    r = X - centre
    along = np.zeros_like(r) if axis is None else np.outer(r @ axis, axis)
    r = r - along
    dist = np.linalg.norm(r, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return along, dist, r / dist[:, None]


def _side(f: Feature, ps: PointSet | None, dist: np.ndarray, u: np.ndarray, R: float | None,
          offset: float) -> tuple[bool | None, str]:
    """INTERNAL (True) or EXTERNAL (False) and the words that say why: the file's
    ``InternalExternal``; where it says neither, the tip-centre radii ``dist`` (D/2 - r for a
    hole, D/2 + r for a shaft, given the nominal diameter D = 2R and probe radius r = ``offset``)
    or the file's point normals (towards or away from the axis; ``u`` the unit radial
    directions); (None, "") when nothing tells."""
    if f.internal is not None:
        return f.internal, "INTERNAL" if f.internal else "EXTERNAL"
    if offset and R is not None:
        internal = bool(np.median(np.abs(dist - (R - offset))) < np.median(np.abs(dist - (R + offset))))
        why = (f"the tip centres lie at D/2 {'-' if internal else '+'} the probe radius "
               f"(nominal D = {2 * R:.6g} mm)")
    elif ps is not None and ps.N is not None and len(ps.N) == len(u):
        internal = bool(np.mean(np.sum(ps.N * u, axis=1)) < 0)
        why = f"the file's point normals point {'towards' if internal else 'away from'} the axis"
    else:
        return None, ""
    return internal, f"{'INTERNAL' if internal else 'EXTERNAL'}: the file does not say, {why}"


#: nominal elements whose closest points cmmwb computes (nominal_points)
PROJECTABLE = ("Plane", "Circle", "Cylinder", "Sphere")


def nominal_points(doc: QifDocument, f: Feature, ps: PointSet) -> tuple[np.ndarray, np.ndarray, str]:
    """Nominal point and outward nominal normal of every measured point of ``f``: its closest
    point on the file's nominal element (``<Kind>FeatureNominal`` with the ``Diameter`` of its
    definition), and the sentence that says so.

    Plane: the foot of the perpendicular; circle and cylinder: the point of the nominal cylinder
    surface (radius D/2) at the same axial position and angle (a circle is compared in its plane,
    as CMM software reports it); sphere: the radial point at D/2.  When the points are stylus-tip
    centres (``Compensated`` = false) the nominal surface is offset by the probe radius along
    its outward normal (tip centres of a hole lie at D/2 - r, of a shaft at D/2 + r).  The
    outward normal points out of the material: away from the axis for EXTERNAL, towards it for
    INTERNAL; where the file says neither, the side is taken from where the points lie and the
    sentence says so."""
    g, where = f.nominal, f"{f.kind}FeatureMeasurement id={f.id} ({f.name})"
    if f.kind not in PROJECTABLE:
        raise InputError(f"{f.name} is a {f.kind.lower()}: nominal points are computed on nominal "
                         f"{', '.join(k.lower() for k in PROJECTABLE)} only", file=doc.path, where=where)
    if not g:
        raise InputError(f"{f.name} has no nominal element (FeatureItem/FeatureNominalId) to compute "
                         "nominal points on", file=doc.path, where=where)
    X = ps.X_mm
    offset, what = 0.0, "surface points"
    if ps.compensated is False:
        if ps.probe_radius_mm is None:
            raise InputError(f"the points of {f.name} are stylus-tip centres (Compensated = false) "
                             "without ProbeRadius: the nominal tip-centre surface cannot be placed",
                             file=doc.path, where=ps.where)
        offset, what = ps.probe_radius_mm, f"stylus-tip centres, probe radius {ps.probe_radius_mm:.6g} mm"
    if f.kind == "Plane":
        if "Location" not in g or "Normal" not in g:
            raise InputError(f"the nominal plane of {f.name} lacks Location or Normal", file=doc.path,
                             where=where)
        n = g["Normal"]
        X_nom = X - np.outer((X - g["Location"]) @ n - offset, n)
        return X_nom, np.tile(n, (len(X), 1)), (
            f"{f.name}: nominal points = feet of the perpendiculars on the nominal plane"
            + (f" offset by {offset:.6g} mm along its normal" if offset else "") + f" ({what})")
    if "Diameter" not in g:
        raise InputError(f"the nominal {f.kind.lower()} of {f.name} has no Diameter in its definition",
                         file=doc.path, where=where)
    R = g["Diameter"] / 2
    c = g.get("Location", g.get("AxisPoint"))
    if c is None:
        raise InputError(f"the nominal {f.kind.lower()} of {f.name} lacks its centre/axis point",
                         file=doc.path, where=where)
    a = None
    if f.kind != "Sphere":
        a = g.get("Normal", g.get("Direction"))
        if a is None:
            raise InputError(f"the nominal {f.kind.lower()} of {f.name} lacks its axis direction",
                             file=doc.path, where=where)
    along, dist, u = _radial(X, c, a)
    if np.any(dist < 1e-9 * max(R, 1.0)):
        raise InputError(f"a point of {f.name} lies on the nominal axis/centre: no closest point",
                         file=doc.path, where=ps.where)
    internal, side = _side(f, ps, dist, u, R, offset)
    if internal is None:
        raise InputError(f"the file does not say whether {f.name} is INTERNAL or EXTERNAL "
                         "(InternalExternal), and its surface points have no normals to tell; "
                         "cmmwb cannot place the outward normals", file=doc.path, where=where)
    rho = R - offset if internal else R + offset
    X_nom = c + along + rho * u
    N = -u if internal else u
    return X_nom, N, (f"{f.name}: nominal points = the nominal {f.kind.lower()} (D = {2 * R:.6g} mm, {side}) "
                      f"at radius {rho:.6g} mm, closest to each point"
                      + (" at the same axial position" if f.kind != "Sphere" else "") + f" ({what})")
