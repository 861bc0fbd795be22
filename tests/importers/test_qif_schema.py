"""QIF out is schema-valid: the copies `cmmwb import FILE.qif --out COPY.qif` writes, checked
against the QIF 3.0 XML schema (tests/data/qif/schemas/3.0, validated with `xmlschema`).

- QIF 3.0 (the community sample QIF_PTS_SAMPLE.QIF): the annotated copy has exactly the schema
  errors of the original -- none added.  The original's own errors (14 with xmlschema 4.3.2)
  are keyrefs to feature items that `xmlschema` does not collect (the ids are there; see the
  test).
- QIF 2.1 (NIST's plate results): no QIF 2.1 schema is public, so the copy is checked by the rule
  that matters: it differs from the original only by ``combinedUncertainty`` attributes, each on
  the ``Value`` of a characteristic actual whose QIF 3.0 counterpart (``<Kind>Characteristic
  Measurement/Value``) derives from ``MeasuredDecimalType``, which declares the attribute, and
  each value valid for that attribute's type (``NonNegativeDecimalType``).
Negative controls show that both checks catch an uncertainty in a place the schema does not give
it.
"""

from collections import Counter
from xml.etree import ElementTree as ET

import pytest

from cmmwb.generator.importers import run_import

from tests.helpers import ROOT

DATA = ROOT / "tests" / "data" / "qif"
NIST = DATA / "nist_sms_plate_results.qif"
SAMPLE = DATA / "QIF_PTS_SAMPLE.QIF"
QIF3_XSD = DATA / "schemas" / "3.0" / "QIFApplications" / "QIFDocument.xsd"
U = "combinedUncertainty"


@pytest.fixture(scope="module")
def qif3():
    """The QIF 3.0 schema (about 5 s to build); local files only, nothing fetched."""
    import xmlschema

    return xmlschema.XMLSchema(str(QIF3_XSD.resolve()), allow="local")


@pytest.fixture(scope="module")
def copies(tmp_path_factory):
    """The annotated copies, written as `cmmwb import FILE --out COPY.qif` writes them."""
    d = tmp_path_factory.mktemp("qif_out")
    run_import(SAMPLE, d / "sample_u.qif")
    run_import(NIST, d / "plate_u.qif")
    return {"3.0": d / "sample_u.qif", "2.1": d / "plate_u.qif"}


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def schema_errors(schema, path) -> Counter:
    return Counter((e.reason, e.path) for e in schema.iter_errors(str(path)))


# --- QIF 3.0: validated against the schema ---------------------------------------------------

def test_the_qif3_copy_adds_no_schema_error_to_the_original(qif3, copies):
    out = copies["3.0"]
    assert sum(U in v.attrib for v in ET.parse(out).getroot().iter()) == 11
    assert schema_errors(qif3, out) == schema_errors(qif3, SAMPLE)


def test_the_qif3_originals_own_errors_are_feature_item_keyrefs_whose_ids_exist(qif3):
    """The sample's errors (14 with xmlschema 4.3.2) are all 'value not found for
    FeatureItemIdKey', yet every one of those ids is the id of an element of
    Features/FeatureItems, as that key's selector (t:Features/t:FeatureItems/t:*) asks.
    xmlschema resolves that wildcard to the abstract head FeatureItem only, not to its
    substitution group (PlaneFeatureItem, CircleFeatureItem, ...), and so collects none of
    them: a limitation of the validator, not of the file."""
    errors = list(qif3.iter_errors(str(SAMPLE)))
    root = ET.parse(SAMPLE).getroot()
    ns = {"t": "http://qifstandards.org/xsd/qif3"}
    item_ids = {int(e.get("id")) for e in root.findall("t:Features/t:FeatureItems/*", ns)}
    for e in errors:
        assert "not found for XsdKey(name='t:FeatureItemIdKey')" in e.reason
        value = e.reason.split("Decimal('")[1].split("')")[0]
        assert int(value) in item_ids


@pytest.mark.parametrize("where, value, element, reason", [
    ("item id", None, "CharacteristicItemId", "'combinedUncertainty' attribute not allowed"),
    ("value", "-0.001", "Value", "value has to be greater or equal than Decimal('0')"),
])
def test_an_uncertainty_the_qif3_schema_has_no_place_for_is_a_new_error(
        qif3, copies, tmp_path, where, value, element, reason):
    """Negative control: the validation above sees an uncertainty moved onto the item id (no
    such attribute there) or made negative (NonNegativeDecimalType)."""
    ET.register_namespace("", "http://qifstandards.org/xsd/qif3")
    root = ET.parse(copies["3.0"]).getroot()
    m = next(a for a in root.iter() if _local(a.tag).endswith("CharacteristicMeasurement")
             and U in a.find("{*}Value").attrib)
    u = m.find("{*}Value").attrib.pop(U)
    m.find(f"{{*}}{element}").set(U, value or u)
    bad = tmp_path / "bad.qif"
    ET.ElementTree(root).write(bad, encoding="utf-8", xml_declaration=True)
    [(new_reason, new_path)] = schema_errors(qif3, bad) - schema_errors(qif3, SAMPLE)
    assert reason in new_reason
    assert new_path.endswith(f"/{_local(m.tag)}/{element}")


# --- QIF 2.1: no public schema; the copy's additions checked against QIF 3.0's types ----------

def additions(original, copy) -> tuple[list[tuple[str, str, str]], list[str]]:
    """Walk both documents in step: every added attribute as (parent tag, element tag,
    attribute=value), and every other difference (tag, text, tail, an attribute changed or
    removed, a child added or removed) as a sentence."""
    added, other = [], []

    def walk(a, b, parent, path):
        if a.tag != b.tag:
            other.append(f"{path}: element {a.tag} became {b.tag}")
            return
        if (a.text, a.tail) != (b.text, b.tail):
            other.append(f"{path}: text changed")
        for k, v in a.attrib.items():
            if b.attrib.get(k) != v:
                other.append(f"{path}: attribute {k} changed or removed")
        for k in b.attrib.keys() - a.attrib.keys():
            added.append((_local(parent.tag), _local(b.tag), f"{k}={b.attrib[k]}"))
        if len(a) != len(b):
            other.append(f"{path}: {len(a)} children became {len(b)}")
        for i, (ca, cb) in enumerate(zip(a, b)):
            walk(ca, cb, a, f"{path}/{_local(ca.tag)}[{i}]")

    ra, rb = ET.parse(original).getroot(), ET.parse(copy).getroot()
    walk(ra, rb, ra, _local(ra.tag))
    return added, other


def not_allowed_by_qif3(qif3, added) -> list[str]:
    """The additions QIF 3.0 gives no place: a QIF 2 ``<Kind>CharacteristicActual`` is QIF 3's
    ``<Kind>CharacteristicMeasurement``; its child must be declared there with a type derived
    from MeasuredDecimalType (Units.xsd), declaring the attribute, and the value must be valid
    for the attribute's type."""
    measured = qif3.types["MeasuredDecimalType"]
    bad = []
    for parent, tag, attr in added:
        name, value = attr.split("=", 1)
        kind = parent.removesuffix("CharacteristicActual")
        owner = qif3.types.get(f"{kind}CharacteristicMeasurementType")
        decl = None if owner is None or kind == parent else next(
            (e for e in owner.content.iter_elements() if e.local_name == tag), None)
        a = None if decl is None else decl.type.attributes.get(name)
        if a is None or not decl.type.is_derived(measured) or not a.type.is_valid(value):
            bad.append(f"{parent}/{tag} @{attr}")
    return bad


def test_the_qif21_copy_differs_only_by_uncertainties_where_qif3_values_take_them(qif3, copies):
    added, other = additions(NIST, copies["2.1"])
    assert other == []
    assert len(added) == 37 * 20
    assert {(p, t, a.split("=")[0]) for p, t, a in added} == {
        (f"{k}CharacteristicActual", "Value", U)
        for k in ("Flatness", "Perpendicularity", "Position", "Angle", "Diameter",
                  "DistanceBetween")}
    assert not_allowed_by_qif3(qif3, added) == []


@pytest.mark.parametrize("addition", [
    ("PositionCharacteristicActual", "CharacteristicItemId", f"{U}=0.001"),   # no such attribute
    ("PositionCharacteristicActual", "Value", f"{U}=-0.001"),                 # not >= 0
    ("PositionCharacteristicActual", "Value", f"{U}=1e-3"),                   # not xs:decimal
    ("PositionCharacteristicActual", "Value", "uncertainty=0.001"),           # not declared
    ("Position", "Value", f"{U}=0.001"),                                      # not an actual
])
def test_the_qif21_rule_refuses_what_qif3_has_no_place_for(qif3, addition):
    """Negative control of the rule above."""
    assert not_allowed_by_qif3(qif3, [addition]) == [f"{addition[0]}/{addition[1]} @{addition[2]}"]
