"""QIF (ISO 23952) characteristics: definitions, nominals, items, measured values -- in and out.

Read (QIF 2.x and 3.0, Results and Plans documents; element names are the same in both
namespaces, ``http://qifstandards.org/xsd/qif2`` and ``.../qif3``):

``Characteristics/CharacteristicDefinitions``  ``<Kind>CharacteristicDefinition``: ``Name``,
                                               ``Tolerance`` (``MinValue``/``MaxValue``) or
                                               ``ToleranceValue`` (a zone width),
                                               ``MaterialCondition``, ``ZoneShape``
                                               (``DiametricalZone``), ``DatumReferenceFrameId``
``Characteristics/CharacteristicNominals``     ``CharacteristicDefinitionId``, ``TargetValue``
``Characteristics/CharacteristicItems``        ``Name``, ``CharacteristicNominalId``,
                                               ``FeatureItemIds`` (the features measured)
``MeasurementsResults/.../MeasurementResults`` one per measured part: ``CharacteristicActuals``
                                               (QIF 2) or ``CharacteristicMeasurements`` (QIF
                                               3): ``CharacteristicItemId``, ``Value``,
                                               ``Status/CharacteristicStatusEnum``, the
                                               features measured (``FeatureMeasurementIds``:
                                               their points, where the file has them, are read
                                               by :mod:`generator.importers.qif`), and
                                               ``InspectionStatus``
``Tolerance/DefinedAsLimit``                   false: Min/MaxValue are deviations from the
                                               nominal (limits = TargetValue + them)
``FileUnits/PrimaryUnits``                     ``LinearUnit``/``AngularUnit`` conversions; a
                                               document without FileUnits is read in mm and
                                               degrees (QIF's defaults) and the report says so

Kinds mapped to cmmwb characteristics (:data:`KIND_MAP`); every other kind (user-defined,
profile, runout, concentricity, symmetry, radius, ...) is listed as not supported, by name.

Out: :func:`write_uncertainties` writes a copy of the document with the attribute
``combinedUncertainty`` (a standard uncertainty, in the value's unit) on the ``Value`` of each
characteristic actual -- in QIF 3.0 that ``Value`` is a ``MeasuredLinearValueType`` /
``MeasuredAngularValueType``, extensions of ``MeasuredDecimalType`` (Units.xsd), which declares
``combinedUncertainty``.  ``meanError`` is not written: cmmwb does not estimate a mean error.
Schema validity of the copy is tested in tests/importers/test_qif_schema.py (docs/import.md says
what is validated against what).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree as ET

from defusedxml import ElementTree as DET

from cmmwb.xlfuncs.limits import coordinate_problem

from ..errors import InputError
from ..workbook.guarded import read_bytes
from .qif import file_units, unique_ids

#: QIF characteristic kinds -> xlfuncs.characteristics types
KIND_MAP = {
    "Flatness": "flatness", "Straightness": "straightness", "Circularity": "roundness",
    "Cylindricity": "cylindricity", "Perpendicularity": "perpendicularity",
    "Parallelism": "parallelism", "Angularity": "angularity", "Position": "position",
    "Diameter": "diameter", "Width": "width", "DistanceBetween": "distance",
    "AngleBetween": "angle", "Angle": "angle",
}
MATERIAL = {"NONE": "RFS", "REGARDLESS": "RFS", "MAXIMUM": "MMC", "LEAST": "LMC",
            "MMC": "MMC", "LMC": "LMC", "RFS": "RFS"}
#: QIF kinds whose values are angles (the file's angular unit)
ANGLE_KINDS = ("Angle", "AngleBetween")


@dataclass
class Definition:
    id: str
    kind: str                          # QIF kind, e.g. "Flatness"
    name: str
    lsl: float | None = None
    usl: float | None = None
    tolerance: float | None = None     # zone width (ToleranceValue)
    material_condition: str | None = None
    diametral: bool = False
    frame_id: str | None = None
    deviations: bool = False           # DefinedAsLimit false: Min/MaxValue relative to nominal

    @property
    def type(self) -> str | None:
        """The cmmwb characteristic type, or None (not supported)."""
        return KIND_MAP.get(self.kind)

    @property
    def zone_problem(self) -> str | None:
        """Why the ``ToleranceValue`` is not a zone the value can be decided against, or None: a
        negative width (NIST's SMS Plate and Cover files have -0.13), or 0 regardless of feature
        size (nothing could conform; 0 at MMC/LMC is a zero tolerance whose zone is the bonus)."""
        if self.tolerance is None:
            return None
        if self.tolerance < 0:
            return f"ToleranceValue {self.tolerance:g} is negative, which a zone width cannot be"
        if self.tolerance == 0 and self.material_condition in (None, "RFS"):
            return "ToleranceValue 0 regardless of feature size: a zone of width 0, nothing could conform"
        return None


@dataclass
class Item:
    id: str
    name: str
    definition: Definition
    nominal: float | None
    feature_ids: list[str] = field(default_factory=list)
    #: the feature's side from its FeatureDefinition's InternalExternal: True a hole, False a pin
    internal: bool | None = None

    @property
    def lsl(self) -> float | None:
        d = self.definition
        if d.lsl is None or not d.deviations:
            return d.lsl
        return None if self.nominal is None else self.nominal + d.lsl

    @property
    def usl(self) -> float | None:
        d = self.definition
        if d.usl is None or not d.deviations:
            return d.usl
        return None if self.nominal is None else self.nominal + d.usl


@dataclass
class Actual:
    item: Item
    value: float | None
    status: str | None                 # the file's own PASS / FAIL / ...
    feature_ids: list[str] = field(default_factory=list)   # QIF 3 FeatureMeasurementIds


@dataclass
class Part:
    id: str
    status: str | None                 # InspectionStatus of the part
    actuals: list[Actual]


@dataclass
class QifCharacteristics:
    path: Path
    version: str
    namespace: str
    items: list[Item]
    parts: list[Part]
    units: str                         # how lengths and angles were read
    has_points: bool
    unsupported: dict[str, int]        # QIF kind -> number of definitions
    mm_per_unit: float = 1.0           # the file's length unit in mm (qif.file_units)
    deg_per_unit: float = 1.0          # the file's angle unit in degrees
    length_unit: str = "mm"            # their names as the file gives them
    angle_unit: str = "degree"

    def unit_of(self, item: Item) -> str:
        """The name of the file's unit of ``item``'s values."""
        return self.angle_unit if self.is_angle(item) else self.length_unit

    def is_angle(self, item: Item) -> bool:
        return item.definition.kind in ANGLE_KINDS

    def to_file_unit(self, item: Item, value: float) -> float:
        """A value or u of ``item`` in mm (degrees for an angle) expressed in the file's unit."""
        return value / (self.deg_per_unit if self.is_angle(item) else self.mm_per_unit)

    def size_actual(self, part: Part, actual: Actual) -> Actual | None:
        """The measured diameter of the same measured feature as ``actual`` (a position) in
        ``part``: the measurement whose FeatureActualIds / FeatureMeasurementIds are the
        position's, of a diameter with both limits; None when the part has none."""
        if not actual.feature_ids:
            return None
        return next((b for b in part.actuals if b.item.definition.type == "diameter"
                     and b.feature_ids == actual.feature_ids and b.item.lsl is not None
                     and b.item.usl is not None), None)

    def size_of(self, item: Item) -> Item | None:
        """The diameter characteristic of the feature of the position ``item``, whose limits give
        the bonus at MMC/LMC (ASME Y14.5-2018 5.8.1): measured on the same feature as the position
        (NIST's SMS files: DIAMETER4, a pattern of four holes, measured on feature 34 like
        POSITION1), else the diameter item of the same FeatureItemIds; None when the file has none."""
        for p in self.parts:
            for a in p.actuals:
                if a.item is item:
                    b = self.size_actual(p, a)
                    if b is not None:
                        return b.item
        if len(item.feature_ids) != 1:
            return None
        return next((it for it in self.items if it.definition.type == "diameter"
                     and it.feature_ids == item.feature_ids and it.lsl is not None and it.usl is not None), None)

    def bonus_problem(self, item: Item) -> str | None:
        """Why a position at MMC/LMC cannot carry its bonus, or None (RFS, or a size to take it from)."""
        d = item.definition
        if d.type != "position" or d.material_condition not in ("MMC", "LMC"):
            return None
        size = self.size_of(item)
        if size is None:
            return (f"at {d.material_condition} but the file has no diameter of its feature "
                    f"({', '.join(item.feature_ids) or 'none named'}) to take the bonus from")
        if item.internal is None:
            return (f"at {d.material_condition}, size {size.name}, but the file does not say whether the feature is "
                    "a hole or a pin (InternalExternal), which decides the MMC limit")
        return None

    def table(self) -> list[dict]:
        """One row per (part, characteristic): name, QIF kind, cmmwb type, nominal,
        tolerance, measured value and the file's status."""
        out = []
        for p in self.parts:
            for a in p.actuals:
                d = a.item.definition
                out.append({"part": p.id, "name": a.item.name, "kind": d.kind, "type": d.type,
                            "nominal": a.item.nominal, "lsl": a.item.lsl, "usl": a.item.usl,
                            "tolerance": d.tolerance, "material_condition": d.material_condition,
                            "diametral": d.diametral, "value": a.value, "status": a.status,
                            "features": list(a.feature_ids)})
        return out


def _local(tag) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _child(el, name):
    for c in el:
        if _local(c.tag) == name:
            return c
    return None


def _text(el, name):
    c = _child(el, name)
    return None if c is None or c.text is None else c.text.strip()


def _num(path, el, name, where, scale=1.0, *, angle=False):
    """The number of the child ``name`` of ``el`` times ``scale`` (to mm, or degrees for an
    ``angle``), None without one; a length beyond the coordinate range (+-100 m) is refused like
    every coordinate cmmwb reads (xlfuncs/limits.py)."""
    t = _text(el, name)
    if t is None:
        return None
    try:
        v = float(t)
    except ValueError:
        raise InputError(f"{name} is not a number: {t[:40]!r}", file=path, where=where) from None
    if not math.isfinite(v):
        raise InputError(f"{name} is not finite", file=path, where=where)
    problem = None if angle else coordinate_problem(v * scale)
    if problem:
        raise InputError(f"{name} {t.strip()[:40]}: {problem}", file=path, where=where)
    return v * scale


def read_characteristics(path: str | Path) -> QifCharacteristics:
    """The characteristics of a QIF document (module docstring)."""
    path = Path(path)
    data = read_bytes(path, "import")
    try:
        root = DET.fromstring(data)
    except Exception as e:   # defusedxml raises for DTDs/entities, ParseError for bad XML
        raise InputError(f"not a readable QIF document ({e})", file=path) from None
    if _local(root.tag) != "QIFDocument":
        raise InputError(f"not a QIF document (root element {_local(root.tag)!r})", file=path)
    ns = root.tag[1:].split("}")[0] if root.tag.startswith("{") else ""
    fu = file_units(path, root)
    unique_ids(path, root)
    mm, deg, units = fu.mm_per_unit, fu.deg_per_unit, fu.text
    chars = _child(root, "Characteristics")
    if chars is None:
        raise InputError("the document has no Characteristics section", file=path)
    defs: dict[str, Definition] = {}
    unsupported: dict[str, int] = {}
    for d in _child(chars, "CharacteristicDefinitions") or []:
        kind = _local(d.tag).replace("CharacteristicDefinition", "")
        where = f"CharacteristicDefinitions/{_local(d.tag)} id={d.get('id')}"
        scale = deg if kind in ANGLE_KINDS else mm
        tol = _child(d, "Tolerance")
        zs = _child(d, "ZoneShape")
        df = Definition(
            id=d.get("id"), kind=kind, name=_text(d, "Name") or d.get("id"),
            lsl=None if tol is None else _num(path, tol, "MinValue", where, scale, angle=kind in ANGLE_KINDS),
            usl=None if tol is None else _num(path, tol, "MaxValue", where, scale, angle=kind in ANGLE_KINDS),
            tolerance=_num(path, d, "ToleranceValue", where, mm),
            material_condition=MATERIAL.get(_text(d, "MaterialCondition") or "", None),
            diametral=zs is not None and _child(zs, "DiametricalZone") is not None,
            frame_id=_text(d, "DatumReferenceFrameId"),
            deviations=tol is not None and (_text(tol, "DefinedAsLimit") or "true") == "false")
        defs[df.id] = df
        if df.type is None:
            unsupported[kind] = unsupported.get(kind, 0) + 1
    nominals = {}
    for n in _child(chars, "CharacteristicNominals") or []:
        did = _text(n, "CharacteristicDefinitionId")
        if did not in defs:
            raise InputError(f"nominal {n.get('id')} names an unknown definition {did!r}",
                             file=path, where="CharacteristicNominals")
        d = defs[did]
        scale = deg if d.kind in ANGLE_KINDS else mm
        nominals[n.get("id")] = (d, _num(path, n, "TargetValue", f"nominal {n.get('id')}", scale,
                                         angle=d.kind in ANGLE_KINDS))
    feature_items, measured_features, side = _features(root)
    items: dict[str, Item] = {}
    for it in _child(chars, "CharacteristicItems") or []:
        nid = _text(it, "CharacteristicNominalId")
        if nid not in nominals:
            raise InputError(f"item {it.get('id')} names an unknown nominal {nid!r}", file=path,
                             where="CharacteristicItems")
        d, target = nominals[nid]
        fids = [c.text.strip() for c in (_child(it, "FeatureItemIds") or []) if c.text]
        missing = [f for f in fids if f not in feature_items]
        if missing:
            raise InputError(f"FeatureItemIds names feature {missing[0]}, which the file does not have (no "
                             "FeatureItem with that id): its points and size would be another's or none",
                             file=path, where=f"CharacteristicItems/CharacteristicItem id={it.get('id')}")
        sides = {side.get(f) for f in fids}
        items[it.get("id")] = Item(it.get("id"), _text(it, "Name") or d.name, d, target, fids,
                                   sides.pop() if len(sides) == 1 else None)
    parts = []
    for mr in root.iter():
        if _local(mr.tag) != "MeasurementResults":
            continue
        mc = _child(mr, "MeasuredCharacteristics")
        acts = [] if mc is None else (_child(mc, "CharacteristicActuals")      # QIF 2
                                      or _child(mc, "CharacteristicMeasurements") or [])   # QIF 3
        actuals = []
        for a in acts:
            iid = _text(a, "CharacteristicItemId")
            if iid not in items:
                raise InputError(f"actual {a.get('id')} names an unknown item {iid!r}", file=path,
                                 where=f"MeasurementResults id={mr.get('id')}")
            it = items[iid]
            scale = deg if it.definition.kind in ANGLE_KINDS else mm
            st = _child(a, "Status")
            fm = _child(a, "FeatureMeasurementIds") or _child(a, "FeatureActualIds") or []
            here = f"MeasurementResults id={mr.get('id')}/{_local(a.tag)} id={a.get('id')}"
            missing = [c.text.strip() for c in fm if c.text and c.text.strip() not in measured_features]
            if missing:
                raise InputError(f"names the measured feature {missing[0]}, which the file does not have (no "
                                 "FeatureMeasurement or FeatureActual with that id)", file=path, where=here)
            actuals.append(Actual(it, _num(path, a, "Value", here, scale, angle=it.definition.kind in ANGLE_KINDS),
                                  None if st is None else _text(st, "CharacteristicStatusEnum"),
                                  [c.text.strip() for c in fm if c.text]))
        ins = _child(mr, "InspectionStatus")
        parts.append(Part(mr.get("id"), None if ins is None else _text(ins, "InspectionStatusEnum"),
                          actuals))
    has_points = any(_local(e.tag) in ("MeasuredPointSet", "MeasurePoint", "PointList")
                     for e in root.iter())
    return QifCharacteristics(path=path, version=root.get("versionQIF", "?"), namespace=ns,
                              items=list(items.values()), parts=parts, units=units,
                              has_points=has_points, unsupported=unsupported, mm_per_unit=mm, deg_per_unit=deg,
                              length_unit=fu.length_name, angle_unit=fu.angle_name)


def _features(root) -> tuple[set[str], set[str], dict[str, bool | None]]:
    """(ids of the FeatureItems, ids of the feature measurements/actuals, FeatureItem id -> its
    side: True INTERNAL, False EXTERNAL, None not said) of the document."""
    items, measured, item_nominal, nominal_def, definition_side = set(), set(), {}, {}, {}
    for el in root.iter():
        tag, fid = _local(el.tag), el.get("id")
        if not fid:
            continue
        if tag.endswith("FeatureItem"):
            items.add(fid)
            item_nominal[fid] = _text(el, "FeatureNominalId")
        elif tag.endswith(("FeatureMeasurement", "FeatureActual")):
            measured.add(fid)
        elif tag.endswith("FeatureNominal"):
            nominal_def[fid] = _text(el, "FeatureDefinitionId")
        elif tag.endswith("FeatureDefinition"):
            definition_side[fid] = {"INTERNAL": True, "EXTERNAL": False}.get(_text(el, "InternalExternal") or "")
    side = {i: definition_side.get(nominal_def.get(n or "") or "") for i, n in item_nominal.items()}
    return items, measured, side


def decimal_text(u: float, digits: int = 3) -> str:
    """u with ``digits`` significant digits in plain decimal notation (xs:decimal has no
    exponent): 0.000246, 1.23."""
    if u == 0:
        return "0"
    places = max(0, digits - 1 - math.floor(math.log10(abs(u))))
    return f"{u:.{places}f}"


def write_uncertainties(src: str | Path, u_by_item: dict[str, float], out: str | Path,
                        sources: dict[str, str] | None = None, header: str | None = None) -> int:
    """A copy of the QIF document ``src`` with ``combinedUncertainty`` (in the value's unit of
    the file) on the Value of every characteristic actual whose item is in ``u_by_item``;
    returns the number of values annotated.  ``sources``: per item, where its u comes from, written
    as an XML comment just before each annotated Value (``<!-- cmmwb: combinedUncertainty from a
    simulated stand-in part ... -->``); ``header``: a comment at the start of the document.  The
    rest of the document is unchanged in content (ElementTree re-serialises it; the namespace
    stays the default one; comments are invisible to the schema)."""
    src = Path(src)
    data = read_bytes(src, "import")
    root = DET.fromstring(data)
    ns = root.tag[1:].split("}")[0] if root.tag.startswith("{") else ""
    if ns:
        ET.register_namespace("", ns)
    n = 0
    actuals = [a for a in root.iter()
               if isinstance(a.tag, str) and _local(a.tag).endswith(("CharacteristicActual", "CharacteristicMeasurement"))]
    for a in actuals:
        iid = _text(a, "CharacteristicItemId")
        v = _child(a, "Value")
        if iid in u_by_item and v is not None:
            u = u_by_item[iid]
            if not (math.isfinite(u) and u >= 0):
                raise ValueError(f"uncertainty of item {iid} must be finite and >= 0")
            v.set("combinedUncertainty", decimal_text(u))
            if sources and iid in sources:
                a.insert(list(a).index(v), ET.Comment(f" cmmwb: combinedUncertainty {_comment(sources[iid])} "))
            n += 1
    if header:
        root.insert(0, ET.Comment(f" {_comment(header)} "))
    tree = ET.ElementTree(root)
    out = Path(out)
    tree.write(out, encoding="utf-8", xml_declaration=True)
    return n


def _comment(text: str) -> str:
    """Text safe inside an XML comment (no '--', no trailing '-')."""
    while "--" in text:
        text = text.replace("--", "-")
    return text.rstrip("-")
