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

from ..errors import InputError
from ..workbook.guarded import read_bytes

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

#: the QIF characteristic kinds whose values are angles (read in deg; every other kind in mm)
ANGULAR_KINDS = ("Angle", "AngleBetween")


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


@dataclass
class Item:
    id: str
    name: str
    definition: Definition
    nominal: float | None
    feature_ids: list[str] = field(default_factory=list)

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


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _child(el, name):
    for c in el:
        if _local(c.tag) == name:
            return c
    return None


def _text(el, name):
    c = _child(el, name)
    return None if c is None or c.text is None else c.text.strip()


def _num(path, el, name, where, scale=1.0):
    t = _text(el, name)
    if t is None:
        return None
    try:
        v = float(t)
    except ValueError:
        raise InputError(f"{name} is not a number: {t[:40]!r}", file=path, where=where) from None
    if not math.isfinite(v):
        raise InputError(f"{name} is not finite", file=path, where=where)
    return v * scale


def _units(root) -> tuple[float, float, str]:
    """(mm per file length unit, deg per file angle unit, description)."""
    fu = _child(root, "FileUnits")
    if fu is None:
        return 1.0, 1.0, "no FileUnits in the file: lengths read as mm, angles as degrees"
    pu = _child(fu, "PrimaryUnits")
    lin, ang = 1.0, 1.0
    desc = []
    for key, unit in (("LinearUnit", "mm"), ("AngularUnit", "deg")):
        el = None if pu is None else _child(pu, key)
        if el is None:
            continue
        name = _text(el, "UnitName") or "?"
        conv = _child(el, "UnitConversion")
        f = _num(None, conv, "Factor", key) if conv is not None else None
        if key == "LinearUnit":
            lin = 1.0 if f is None and name.lower() in ("mm", "millimeter", "millimetre") else (
                (f or 1.0) * 1000.0)
        else:
            ang = 1.0 if f is None and name.lower().startswith("deg") else (
                math.degrees(f) if f is not None else 1.0)
        desc.append(f"{key} {name}")
    return lin, ang, ", ".join(desc) or "FileUnits without linear/angular units: mm, degrees"


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
    mm, deg, units = _units(root)
    chars = _child(root, "Characteristics")
    if chars is None:
        raise InputError("the document has no Characteristics section", file=path)
    defs: dict[str, Definition] = {}
    unsupported: dict[str, int] = {}
    for d in _child(chars, "CharacteristicDefinitions") or []:
        kind = _local(d.tag).replace("CharacteristicDefinition", "")
        where = f"CharacteristicDefinitions/{_local(d.tag)} id={d.get('id')}"
        scale = deg if kind in ANGULAR_KINDS else mm
        tol = _child(d, "Tolerance")
        zs = _child(d, "ZoneShape")
        df = Definition(
            id=d.get("id"), kind=kind, name=_text(d, "Name") or d.get("id"),
            lsl=None if tol is None else _num(path, tol, "MinValue", where, scale),
            usl=None if tol is None else _num(path, tol, "MaxValue", where, scale),
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
        scale = deg if d.kind in ANGULAR_KINDS else mm
        nominals[n.get("id")] = (d, _num(path, n, "TargetValue", f"nominal {n.get('id')}", scale))
    items: dict[str, Item] = {}
    for it in _child(chars, "CharacteristicItems") or []:
        nid = _text(it, "CharacteristicNominalId")
        if nid not in nominals:
            raise InputError(f"item {it.get('id')} names an unknown nominal {nid!r}", file=path,
                             where="CharacteristicItems")
        d, target = nominals[nid]
        fids = [c.text.strip() for c in (_child(it, "FeatureItemIds") or []) if c.text]
        items[it.get("id")] = Item(it.get("id"), _text(it, "Name") or d.name, d, target, fids)
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
            scale = deg if it.definition.kind in ANGULAR_KINDS else mm
            st = _child(a, "Status")
            fm = _child(a, "FeatureMeasurementIds") or _child(a, "FeatureActualIds") or []
            actuals.append(Actual(it, _num(path, a, "Value", f"actual {a.get('id')}", scale),
                                  None if st is None else _text(st, "CharacteristicStatusEnum"),
                                  [c.text.strip() for c in fm if c.text]))
        ins = _child(mr, "InspectionStatus")
        parts.append(Part(mr.get("id"), None if ins is None else _text(ins, "InspectionStatusEnum"),
                          actuals))
    has_points = any(_local(e.tag) in ("MeasuredPointSet", "MeasurePoint", "PointList")
                     for e in root.iter())
    return QifCharacteristics(path=path, version=root.get("versionQIF", "?"), namespace=ns,
                              items=list(items.values()), parts=parts, units=units,
                              has_points=has_points, unsupported=unsupported)


def decimal_text(u: float, digits: int = 3) -> str:
    """u with ``digits`` significant digits in plain decimal notation (xs:decimal has no
    exponent): 0.000246, 1.23."""
    if u == 0:
        return "0"
    places = max(0, digits - 1 - math.floor(math.log10(abs(u))))
    return f"{u:.{places}f}"


def write_uncertainties(src: str | Path, u_by_item: dict[str, float], out: str | Path) -> int:
    """A copy of the QIF document ``src`` with ``combinedUncertainty`` (in the value's unit of
    the file) on the Value of every characteristic actual whose item is in ``u_by_item``;
    returns the number of values annotated.  The rest of the document is unchanged in content
    (ElementTree re-serialises it; the namespace stays the default one)."""
    src = Path(src)
    data = read_bytes(src, "import")
    root = DET.fromstring(data)
    ns = root.tag[1:].split("}")[0] if root.tag.startswith("{") else ""
    if ns:
        ET.register_namespace("", ns)
    n = 0
    for a in root.iter():
        if not _local(a.tag).endswith(("CharacteristicActual", "CharacteristicMeasurement")):
            continue
        iid = _text(a, "CharacteristicItemId")
        v = _child(a, "Value")
        if iid in u_by_item and v is not None:
            u = u_by_item[iid]
            if not (math.isfinite(u) and u >= 0):
                raise ValueError(f"uncertainty of item {iid} must be finite and >= 0")
            v.set("combinedUncertainty", decimal_text(u))
            n += 1
    tree = ET.ElementTree(root)
    out = Path(out)
    tree.write(out, encoding="utf-8", xml_declaration=True)
    return n
