"""A documented simulated measurement for a QIF results file that has characteristics but no
points (NIST's SMS test bed files, for example): the uncertainty of each characteristic comes
from the same characteristic on a stand-in part measured by the cmmwb point-cloud model.

The results file carries each characteristic's kind, nominal and tolerance, not the part's
geometry.  The stand-in part is built from those alone and says so:

* a plate 260 x 160 x 12 mm; datum A its bottom face (z = 0, 20 points), B its left face
  (x = 0) and C its front face (y = 0), 6 points each -- the frame A|B|C (the file's datum
  reference frames are used as A|B|C; their datum features are not in a results file);
* per diameter: a through hole of the nominal diameter (TargetValue, else the middle of the
  limits) on a grid of 20 mm pitch, 2 sections (z = 3, 9) of 6 points;
* per perpendicularity / position with a diametral zone: a 10 mm hole of its own (the axis to A;
  the position at its grid place in A|B|C);
* per angle that belongs to one feature (QIF "Angle" named "Cone Angle ..."): a 90 deg
  countersink, a cone with 2 sections of 8 points;
* per distance: two 4 mm holes at the nominal distance along x;
* the flatness of the plate's face A.

Every feature carries planted errors from a seeded generator (position 10 µm, axis tilt 5 µm,
form 1 µm): the u of a characteristic depends on the point layout and on V_X, hardly on these.
Characteristics of other kinds (straightness, width, ... -- not in the NIST files) are not
simulated and are named.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import characteristics as ch
from cmmwb.xlfuncs import pointcloud as pc

from ..errors import InputError
from ..workbook.atomic import replacing
from .qif_characteristics import QifCharacteristics, read_characteristics, write_uncertainties

#: the Forbes 2025 point-cloud model of the stand-in measurement (MPE1-like, Table 3)
PARAMS = pc.Parameters(sigma_R_um=0.2, sigma_S_ppm=0.7, sigma_Sa_ppm=0.8, sigma_Q_ppm=0.9,
                       sigma_PQ_um=0.2, sigma_ET_um=0.3, lambda_ET_mm=150, sigma_ER_urad=4.0,
                       lambda_ER_mm=350, sigma_P0_um=0.1, sigma_P_um=0.15, lambda_P=0.5)
PROBES = (pc.Probe("P1", (0.0, 0.0, -50.0)),)
PITCH_MM = 20.0
COLUMNS = 12


class _Builder:
    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)
        self.X: list[np.ndarray] = []
        self.N: list[np.ndarray] = []
        self.features: list[ch.FeatureSpec] = []
        self.m = 0
        self.slot = 0

    def add(self, name, element, P, N, **kw):
        self.X.append(P)
        self.N.append(N)
        self.features.append(ch.FeatureSpec(name, element, tuple(range(self.m, self.m + len(P))), **kw))
        self.m += len(P)

    def place(self):
        r, c = divmod(self.slot, COLUMNS)
        self.slot += 1
        return 20.0 + PITCH_MM * c, 20.0 + PITCH_MM * r

    def hole(self, name, x, y, d, n=6, levels=(3.0, 9.0)):
        e = self.rng.normal(0, 0.010, 2)
        t = self.rng.normal(0, 0.005, 2)
        P, N = [], []
        for k, z in enumerate(levels):
            for j in range(n):
                th = 2 * np.pi * j / n + 0.4 * k
                rr = d / 2 + 0.001 * self.rng.uniform(-1, 1)
                c = np.array([x, y]) + e + t * (z - 6.0) / 12.0
                P.append([c[0] + rr * np.cos(th), c[1] + rr * np.sin(th), z])
                N.append([-np.cos(th), -np.sin(th), 0.0])
        self.add(name, "cylinder", np.array(P), np.array(N), axis_hint=(0.0, 0.0, 1.0))

    def cone(self, name, x, y, r_top=5.0, half_deg=45.0, n=8):
        phi = np.radians(half_deg)
        P, N = [], []
        for k, z in enumerate((11.0, 9.5)):
            r = r_top - (12.0 - z) * np.tan(phi)
            for j in range(n):
                th = 2 * np.pi * j / n + 0.3 * k
                rr = r + 0.001 * self.rng.uniform(-1, 1)
                P.append([x + rr * np.cos(th), y + rr * np.sin(th), z])
                # material normal of a countersink (opening upwards): towards the axis, up
                N.append([-np.cos(phi) * np.cos(th), -np.cos(phi) * np.sin(th), np.sin(phi)])
        self.add(name, "cone", np.array(P), np.array(N), axis_hint=(0.0, 0.0, -1.0))


def simulate(doc: QifCharacteristics, seed: int = 1):
    """(X_mm, N, features, frames, characteristics, item id -> characteristic name, not
    simulated: list of (item name, reason))."""
    b = _Builder(seed)
    xs, ys = np.linspace(5, 255, 6), np.linspace(5, 155, 4)
    A = np.array([[x, y, 0.001 * b.rng.uniform(-1, 1)] for x in xs for y in ys])
    b.add("A", "plane", A, np.tile([0.0, 0.0, -1.0], (len(A), 1)))
    B = np.array([[0.0, y, z] for y in (20, 80, 140) for z in (3, 9)])
    b.add("B", "plane", B, np.tile([-1.0, 0.0, 0.0], (len(B), 1)))
    C = np.array([[x, 0.0, z] for x in (30, 130, 230) for z in (3, 9)])
    b.add("C", "plane", C, np.tile([0.0, -1.0, 0.0], (len(C), 1)))
    frames = [ch.FrameSpec("ABC", "A", "B", "C")]
    chars, names, skipped = [], {}, []
    holes: dict[str, tuple[float, float]] = {}      # diameter item id -> its hole's place
    for k, it in enumerate(doc.items):
        d = it.definition
        cname = f"q{it.id}"
        t = d.type
        if t is None:
            skipped.append((it.name, f"QIF {d.kind} is not a cmmwb characteristic"))
            continue
        tol = None if d.zone_problem else d.tolerance     # a negative or RFS-zero zone decides nothing
        mid = _middle(it)
        if t == "flatness":
            chars.append(ch.CharacteristicSpec(cname, "flatness", ("A",), method="MZ", tolerance_mm=tol))
        elif t == "diameter":
            x, y = b.place()
            b.hole(f"H{it.id}", x, y, mid)
            holes[it.id] = (x, y)
            chars.append(ch.CharacteristicSpec(cname, "diameter", (f"H{it.id}",), lsl=it.lsl, usl=it.usl))
        elif t == "position" and d.diametral and doc.size_of(it) is not None and not doc.bonus_problem(it):
            # at MMC/LMC: the hole of its size characteristic, the bonus from that size (ASME Y14.5 5.8.1)
            size = doc.size_of(it)
            if size.id not in holes:
                x, y = b.place()
                b.hole(f"H{size.id}", x, y, _middle(size))
                holes[size.id] = (x, y)
            chars.append(ch.CharacteristicSpec(cname, t, (f"H{size.id}",), frame="ABC", zone="diametral",
                                               tolerance_mm=tol, nominal_position_mm=holes[size.id],
                                               material_condition=d.material_condition, size=f"q{size.id}",
                                               internal=bool(it.internal)))
        elif t in ("perpendicularity", "position") and d.diametral:
            x, y = b.place()
            b.hole(f"H{it.id}", x, y, 10.0)
            kw = dict(frame="ABC", zone="diametral", tolerance_mm=tol)
            if t == "position":
                kw["nominal_position_mm"] = (x, y)
            chars.append(ch.CharacteristicSpec(cname, t, (f"H{it.id}",), **kw))
        elif t == "angle" and d.kind == "Angle":
            x, y = b.place()
            b.cone(f"K{it.id}", x, y, half_deg=(mid or 90.0) / 2)
            chars.append(ch.CharacteristicSpec(cname, "cone_angle", (f"K{it.id}",), nominal=mid,
                                               lsl=it.lsl, usl=it.usl))
        elif t == "distance" and mid is not None:
            x, y = b.place()
            b.slot += int(np.ceil(mid / PITCH_MM))
            b.hole(f"D{it.id}a", x, y, 4.0)
            b.hole(f"D{it.id}b", x + mid, y, 4.0)
            chars.append(ch.CharacteristicSpec(cname, "distance", (f"D{it.id}a", f"D{it.id}b"),
                                               nominal=mid, lsl=it.lsl, usl=it.usl))
        else:
            skipped.append((it.name, f"{t} is not simulated on the stand-in plate"))
            continue
        names[it.id] = cname
    return (np.vstack(b.X), np.vstack(b.N), b.features, frames, chars, names, skipped)


def _middle(it) -> float | None:
    """The nominal of an item: its TargetValue, else the middle of its limits (mm or deg)."""
    if it.nominal is not None:
        return it.nominal
    return 0.5 * (it.lsl + it.usl) if it.lsl is not None and it.usl is not None else None


def uncertainties(doc: QifCharacteristics, seed: int = 1):
    """(item id -> u in the file's unit (mm or deg), results, skipped): every simulated
    characteristic evaluated under V_X (xlfuncs.characteristics)."""
    X, N, feats, frames, chars, names, skipped = simulate(doc, seed)
    cloud = pc.PointCloud(X, N, np.zeros(len(X), int), PROBES)
    jf = ch.fit_features(X, N, feats)
    res = ch.evaluate(jf, frames, chars, pc.V_X_components(cloud, PARAMS))
    by = {r.name: r for r in res}
    items = {it.id: it for it in doc.items}
    u = {}
    for iid, cname in names.items():
        r = by[cname]
        u[iid] = doc.to_file_unit(items[iid], r.u * 1e-3 if r.unit == "mm" else r.u * 1e-6 * 180.0 / np.pi)
    return u, res, skipped


#: QIF feature kinds -> cmmwb elements, and the characteristic types built from one feature's points
POINT_ELEMENTS = {"Plane": "plane", "Circle": "circle", "Cylinder": "cylinder", "Sphere": "sphere"}
POINT_TYPES = {"flatness": ("plane",), "roundness": ("circle",), "cylindricity": ("cylinder",),
               "diameter": ("circle", "cylinder", "sphere")}


def from_points(src: Path, doc: QifCharacteristics) -> tuple[dict[str, float], list[str]]:
    """u (file units) of the characteristics of one measured feature whose points the file holds
    (QIF 3 ``FeatureMeasurementIds``): flatness, circularity (a circle in a coordinate plane),
    cylindricity, diameter -- fitted to the file's points under the stand-in V_X
    (:data:`PARAMS`), normals from the file or from the measured element
    (generator.importers.qif.normals_from_feature).  Returns (u by item id, report lines)."""
    from . import qif

    if not doc.has_points or not doc.parts:
        return {}, []
    qd = qif.read_qif(src)
    feats = {f.id: f for f in qd.features}
    u, lines = {}, []
    for a in doc.parts[0].actuals:
        t = a.item.definition.type
        if t not in POINT_TYPES or len(a.feature_ids) != 1 or a.feature_ids[0] not in feats:
            continue
        f = feats[a.feature_ids[0]]
        el = POINT_ELEMENTS.get(f.kind)
        if el not in POINT_TYPES[t]:
            continue
        ps = qd.points_of(f)
        N, note = (ps.N, "normals from the file") if ps.N is not None else \
            qif.normals_from_feature(qd, f, ps)
        plane = "xy"
        if el == "circle":
            n = np.abs(np.asarray(f.geometry.get("Normal", (0.0, 0.0, 1.0)), float))
            axis = int(np.argmax(n))
            if n[axis] < (1 - 1e-9) * np.linalg.norm(n):
                continue                      # roundness needs a circle in a coordinate plane
            plane = ("yz", "zx", "xy")[axis]
        spec = ch.FeatureSpec("F", el, tuple(range(len(ps.X_mm))), circle_plane=plane)
        kw = {"method": "MZ"} if t in ("flatness", "roundness", "cylindricity") else {}
        c = ch.CharacteristicSpec("c", t, ("F",), **kw)
        cloud = pc.PointCloud(ps.X_mm, N, np.zeros(len(ps.X_mm), int), PROBES)
        r = ch.evaluate(ch.fit_features(ps.X_mm, N, [spec]), [], [c],
                        pc.V_X_components(cloud, PARAMS))[0]
        u[a.item.id] = doc.to_file_unit(a.item, r.u * 1e-3)
        lines.append(f"{a.item.name}: u from the file's {len(ps.X_mm)} points of {f.name} "
                     f"({note}; {'tip centres' if ps.compensated is False else 'surface points'})")
    return u, lines


#: what a u from the stand-in part is, in the report and in the QIF copy
STAND_IN = ("from a simulated stand-in part (the file's nominals on a plate, not this part's points; "
            "MPE1-like model of Forbes 2025 Table 3; generator/importers/qif_simulation.py)")


def item_lines(doc: QifCharacteristics, u: dict[str, float], source: dict[str, str]) -> list[str]:
    """One report line per characteristic: tolerance (and why it cannot be decided against),
    material condition and bonus, every value of the first part (an item measured several times
    per part shows each), u in the file's unit and where it comes from."""
    first = doc.parts[0] if doc.parts else None
    lines = []
    for it in doc.items:
        d = it.definition
        angle = doc.is_angle(it)      # values in deg, else mm (converted from the file's units)
        unit = "deg" if angle else "mm"
        tol = (f"zone {d.tolerance:g} {unit}" if d.tolerance is not None else
               f"{it.lsl:g} .. {it.usl:g} {unit}" if it.lsl is not None and it.usl is not None else "-")
        if d.zone_problem:
            tol += f" ({d.zone_problem}; not decided)"
        if d.type == "position" and d.material_condition in ("MMC", "LMC"):
            why = doc.bonus_problem(it)
            size = doc.size_of(it)
            tol += (f" {why}; not decided at {d.material_condition} (RFS would ignore "
                    "the bonus)" if why else
                    f" at {d.material_condition}, bonus from {size.name} "
                    f"({'hole' if it.internal else 'pin'})")
        vals = [a for a in first.actuals if a.item is it] if first else []
        shown = ", ".join("-" if a.value is None else f"{a.value:g} {unit}" + (f" {a.status}" if a.status else "")
                          for a in vals) or "-"
        count = f" ({len(vals)} measurements)" if len(vals) > 1 else ""
        # u as cmmwb states it everywhere (µm, µrad); the copy carries it in the file's own unit
        uu = "-" if it.id not in u else (
            (f"u = {np.deg2rad(u[it.id]) * 1e6:.3g} µrad" if angle else f"u = {u[it.id] * 1e3:.3g} µm")
            + f" ({source.get(it.id, '')})")
        lines.append(f"{it.name} [{d.kind}]: tolerance {tol}; part {first.id if first else '-'}{count}: {shown}; {uu}")
    return lines


def annotate_file(src: Path, out: Path, *, force: bool = False) -> tuple[list[Path], list[str]]:
    """``cmmwb import FILE.qif --out COPY.qif``: the characteristics of ``src`` listed, their u
    from the file's own points where a characteristic is of one measured feature with points
    (:func:`from_points`), else from the stand-in measurement of this module, and a copy with
    ``combinedUncertainty`` (in the file's own unit) on every supported measured value, each
    preceded by a comment saying where its u comes from."""
    src, out = Path(src), Path(out)
    if out.exists() and not force:
        raise InputError("exists (use --force to replace it)", file=out)
    doc = read_characteristics(src)
    u, res, skipped = uncertainties(doc)
    u_pts, pts_lines = from_points(src, doc)
    u.update(u_pts)
    source = {iid: ("from the file's own points" if iid in u_pts else STAND_IN) for iid in u}
    header = (f"cmmwb import: combinedUncertainty added to {len(u)} characteristics, "
              f"{len(u_pts)} from the file's own points, {len(u) - len(u_pts)} {STAND_IN}; "
              f"standard uncertainties in the file's own units ({doc.length_unit}, {doc.angle_unit}); no meanError")
    with replacing(out, ".qif.tmp") as tmp:
        n = write_uncertainties(src, u, tmp, sources=source, header=header)
    report = [f"QIF {doc.version}: {len(doc.items)} characteristics, {len(doc.parts)} measured "
              f"part(s); units: {doc.units}",
              "points: " + (f"the file has points: {len(u_pts)} characteristics of one measured "
                            "feature get u from them, the others from the stand-in measurement"
                            if doc.has_points else
                            "none in the file -- u from a simulated measurement of a stand-in "
                            "part with the file's nominals (generator/importers/qif_simulation.py)"),
              f"combinedUncertainty written on {n} measured values",
              f"in the file's own units ({doc.length_unit}, {doc.angle_unit}); a comment before each value says "
              "where its u comes from"]
    report += [f"not supported: {k} ({v} definition{'s' if v > 1 else ''})"
               for k, v in sorted(doc.unsupported.items())]
    from_file = {it.name for it in doc.items if it.id in u_pts}
    report += [f"not simulated: {name} ({why})" for name, why in skipped if name not in from_file]
    report += pts_lines
    report += item_lines(doc, u, {iid: ("from the file's points" if iid in u_pts else "stand-in part")
                                  for iid in u})
    return [out], report
