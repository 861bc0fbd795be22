"""A small QIF 3 results file written for tests: a part with a bore ``BORE_1`` (cylinder, internal)
and two balls ``SPH_1``, ``SPH_2`` (spheres), each measured as a point set with point normals and
a nominal element, the names the examples of ``cmmwb import --help`` use.  The public QIF samples
in ``tests/data/qif`` have no point normals and no spheres."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _cylinder(centre, radius: float, depth: float, rings: int = 4, per_ring: int = 12):
    """Points on a bore's wall (axis along z) and their outward normals (into the hole's axis)."""
    X, N = [], []
    for z in np.linspace(-depth * 0.9, -depth * 0.1, rings):
        for t in np.linspace(0, 2 * np.pi, per_ring, endpoint=False):
            r = np.array([np.cos(t), np.sin(t), 0.0])
            X.append(np.asarray(centre) + radius * r + [0, 0, z])
            N.append(-r)                      # material outside the hole: the normal points inwards
    return np.array(X), np.array(N)


def _sphere(centre, radius: float, n: int = 13):
    """Points on the upper half of a ball and their outward normals."""
    X, N = [], []
    for k in range(n):
        el = np.pi / 2 * (0.15 + 0.7 * k / (n - 1))
        az = 2.39996 * k                       # golden angle: spread in azimuth
        u = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        X.append(np.asarray(centre) + radius * u)
        N.append(u)
    return np.array(X), np.array(N)


def _numbers(A) -> str:
    return "\n".join(" ".join(f"{v:.9f}" for v in row) for row in np.atleast_2d(A))


def write_part_qif(path: Path, seed: int = 1) -> Path:
    """The part, measured with 0.2 µm of noise along the normals, to ``path``."""
    rng = np.random.default_rng(seed)
    features = [  # name, QIF kind, internal, diameter (mm), nominal geometry, (points, normals)
        ("BORE_1", "Cylinder", True, 20.0, (50.0, 40.0, 0.0), _cylinder((50.0, 40.0, 0.0), 10.0, 30.0)),
        ("SPH_1", "Sphere", False, 25.0, (150.0, 40.0, 12.5), _sphere((150.0, 40.0, 12.5), 12.5)),
        ("SPH_2", "Sphere", False, 25.0, (250.0, 40.0, 12.5), _sphere((250.0, 40.0, 12.5), 12.5)),
    ]
    definitions, nominals, items, measured, sets = [], [], [], [], []
    for k, (name, kind, internal, dia, centre, (X, N)) in enumerate(features):
        d_id, n_id, i_id, m_id, s_id = (100 * (k + 1) + j for j in range(5))
        X = X + N * rng.normal(0.0, 0.2e-3, (len(X), 1))
        side = "INTERNAL" if internal else "EXTERNAL"
        definitions.append(f'<{kind}FeatureDefinition id="{d_id}"><InternalExternal>{side}</InternalExternal>'
                           f"<Diameter>{dia}</Diameter></{kind}FeatureDefinition>")
        where = (f"<Axis><AxisPoint>{_numbers(centre)}</AxisPoint><Direction>0 0 1</Direction></Axis>"
                 if kind == "Cylinder" else f"<Location>{_numbers(centre)}</Location>")
        nominals.append(f'<{kind}FeatureNominal id="{n_id}"><FeatureDefinitionId>{d_id}</FeatureDefinitionId>'
                        f"{where}</{kind}FeatureNominal>")
        items.append(f'<{kind}FeatureItem id="{i_id}"><FeatureNominalId>{n_id}</FeatureNominalId>'
                     f"<FeatureName>{name}</FeatureName></{kind}FeatureItem>")
        measured.append(f'<{kind}FeatureMeasurement id="{m_id}"><FeatureItemId>{i_id}</FeatureItemId>'
                        f'<PointList n="1"><WholePointSetId>{s_id}</WholePointSetId></PointList>{where}'
                        f"<Diameter>{dia}</Diameter></{kind}FeatureMeasurement>")
        sets.append(f'<MeasuredPointSet id="{s_id}" count="{len(X)}"><Points>{_numbers(X)}</Points>'
                    f"<Normals>{_numbers(N)}</Normals><Compensated>true</Compensated></MeasuredPointSet>")
    text = f"""<?xml version="1.0" encoding="UTF-8"?>
<QIFDocument xmlns="http://qifstandards.org/xsd/qif3" versionQIF="3.0.0" idMax="999">
<FileUnits><PrimaryUnits><LinearUnit><SIUnitName>meter</SIUnitName><UnitName>mm</UnitName>
<UnitConversion><Factor>0.001</Factor></UnitConversion></LinearUnit></PrimaryUnits></FileUnits>
<Features>
<FeatureDefinitions n="{len(features)}">{"".join(definitions)}</FeatureDefinitions>
<FeatureNominals n="{len(features)}">{"".join(nominals)}</FeatureNominals>
<FeatureItems n="{len(features)}">{"".join(items)}</FeatureItems>
</Features>
<MeasurementsResults><MeasurementResultsSet n="1"><MeasurementResults id="1">
<MeasuredFeatures n="{len(features)}">{"".join(measured)}</MeasuredFeatures>
<MeasuredPointSets n="{len(features)}">{"".join(sets)}</MeasuredPointSets>
</MeasurementResults></MeasurementResultsSet></MeasurementsResults>
</QIFDocument>
"""
    Path(path).write_text(text, encoding="utf-8")
    return Path(path)
