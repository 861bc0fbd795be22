"""Candidate effects of the mismatch locator (``docs/recordings.md`` section 4).

Every candidate is an explicit sensitivity of the records to a few parameters, derived from the
physics of the effect: a displacement field delta(x) of the indicated point per unit parameter,
in µm, evaluated at the machine (ram) position u = x - p (Forbes 2025 sections 4.3 and 5.3,
multiple probes) or at the artefact point.

* length record a between ends 1 and 2:  column = n_a . (delta(end 2) - delta(end 1)),
  n_a = (x2 - x1)/||x2 - x1|| (the sensitivity of eq. 29 of Forbes 2025 applied to delta);
* point record i, coordinate c: column = delta_c(point i).

Sign convention: ``measured - true = sum of effects + noise``.  Units of the parameters are those
of docs/recordings.md section 4, so the estimates come out in them directly:

=====================  =========================================================  =========
name                   delta (µm) per unit parameter                              unit
=====================  =========================================================  =========
scale                  1e-3 u                          (x' = (1+s) x)             µm/m
scale_x/_y/_z          1e-3 u_x e_x, ...                                          µm/m
squareness_xy/xz/yz    1e-3 u_y e_x, 1e-3 u_z e_x, 1e-3 u_z e_y  (Forbes eq. 10)  µrad
thermal_expansion      lengths: 1e-3 (T - 20) L;  points: 1e-3 (T - 20)(y - c)    ppm/K
probe_radius           n (outward normal)          (Forbes eq. 26, e_P0)          µm
probe_qualification    e_c for points probed with probe k (k >= 2)                µm
E<R><A>                1e-6 t_A (e_R x p)    t_A = u_A (travel from machine zero) µrad/m
scale_drift            1e-3 (t_s/3600) u                                          µm/m/h
offset_drift           (t_s/3600) e_c             (point records only)            µm/h
E<D><C> (straightness) P_k(s) e_D, k = 2, 3; s = (2 u_C - lo - hi)/(hi - lo)      µm
reversal_x/_y/_z       w e_a, w = +1 approached along +a (n_a < -0.1),           µm
                       -1 along -a (n_a > 0.1), else 0
thermal_gradient_a     lengths: 1e-6 (T - 20) L (m_a - c_a);                      ppm/K/m
                       points: 1e-6 (T - 20) (y_a - c_a)(y - c)
probe_lobing           n (cos k phi, sin k phi), k = 2, 3, 4, per probe            µm
periodic_a             (sin 2 pi t/P, cos 2 pi t/P) e_a, t = u_a - (lo + hi)/2;   µm
                       the period P (mm) found by a scan (:func:`period_grid`)
=====================  =========================================================  =========

Second edition (docs/recordings.md section 7):

* straightness ``EYX``, ``EZX``, ``EXY``, ``EZY``, ``EXZ``, ``EYZ`` (ISO 230-1: the carriage of the
  second letter's axis deviates along the first letter's direction): the orthogonal (Legendre)
  polynomials P_2, P_3 of its travel u_C normalized to [-1, 1] over the travel the records see
  (lo, hi: the smallest and largest ram coordinate of every probing); the linear part is
  squareness and the constant part the alignment, so they are left out.  Estimate: the
  coefficients of P_2 and P_3 in µm (a deviation of c_2 P_2 + c_3 P_3; P_k(±1) = (±1)^k);
* ``reversal_a``: a constant error r whose sign follows the approach direction along the axis
  (backlash of the drive, pre-travel of the probe): the probe approaches against the outward
  normal, so a point with n_a < -0.1 is approached along +a and shifted by +r, with n_a > 0.1 by
  -r; probings nearly perpendicular to a (|n_a| <= 0.1) do not move the axis and are not shifted.
* ``thermal_gradient_a`` (ppm/K per m): the artefact's expansion-coefficient error varies linearly
  along a, Δα = g (x_a - c_a)/1000 ppm/K with c_a the middle of the positions along a (points: the
  centroid); it acts with each record's temperature.  A length integrates it: Δα at its midpoint
  m_a times (T - 20) L; a point moves by Δα (T - 20) (y - c).
* ``probe_lobing``: the probe's effective radius depends on the approach direction: harmonics of
  orders 2-4 of the normal's azimuth phi about the stylus axis (z), per probe, each moving the
  point along its normal, delta = n sum_k (c_k cos k phi + s_k sin k phi).  Order 0 is the probe
  radius error and order 1 a probe offset, so they are left out; a normal along the stylus axis
  (|n_xy| <= 0.1) has no azimuth and no lobing term.  cos k phi and sin k phi are polynomials of
  (n_x, n_y)/|n_xy| (no arctangent: the workbook writes the same products).

* ``periodic_a``: a periodic error of the axis a scale or drive (a ball screw's lead, a grating's
  interpolation error): delta_a = a sin(2 pi t/P) + b cos(2 pi t/P) of the ram coordinate t about
  the middle of the travel.  The period P is not a parameter of the linear model: the search scans
  it (:func:`period_grid`) and reports the p-value with the look-elsewhere correction over the
  periods scanned (Bonferroni over the grid).  Identifiable only where the records sample the
  axis densely: from four probings per cycle at the widest gap between the positions seen along a to three cycles
  over the travel seen, within the plausible pitches 1-200 mm (docs/diagnose.md section 6); a
  sine through a few positions (ISO 10360-2 lengths, a ball plate's grid) fits a bump or a
  straightness as well as a periodic error.

For point records the scale-type effects, thermal expansion and scale drift act about the
centroid c of the nominal points (docs/recordings.md section 6); the rigid alignment absorbs the choice
for the effects that do not vary from record to record.

One table: :data:`EFFECTS` has one entry per effect (its name, family, unit and the words of the
answer); :data:`FAMILIES` the sensitivity columns of each family (effects that differ only by an
axis or a rotation share a family), for length and for point records.  The diagnosis workbook
writes the same columns as formulas from ``generator.diagnosis.formulas.FORMULAS``, keyed by the
same families; ``tests/diagnosis/test_diagnose_effect_formulas.py`` recomputes every effect's columns and
compares them with these cell by cell.  A new effect of an existing family is one entry in
EFFECTS (plus, where it needs something, its check in :func:`_needs`); a new family adds one
entry to FAMILIES and one to FORMULAS.

Over 600 lines but one job, kept whole on purpose (issue 27): it is this one table of effects and
their sensitivity columns (one pair of short functions per family, the period scan of
``periodic_a``); split, the table and its columns would sit in two places and a new effect would
again touch several modules.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

MILLI = 1e-3
MICRO = 1e-6
T_REF_C = 20.0
AXES = "xyz"


@dataclass(frozen=True)
class Effect:
    """One candidate effect: one entry of :data:`EFFECTS`.  ``family`` keys its sensitivity
    columns (:data:`FAMILIES`) and the workbook's formulas of them
    (``generator.diagnosis.formulas.FORMULAS``)."""

    name: str                  # docs/recordings.md section 4 (the key of diagnosis.json)
    family: str                # key of FAMILIES: effects that differ only by an axis share one
    unit: str                  # docs/recordings.md section 5 spelling
    plain: str                 # "a squareness error between x and y"
    hint: str                  # what separates it from look-alikes
    vector: bool = False


def _angular(rot: str, carriage: str) -> Effect:
    about = {"A": "x", "B": "y", "C": "z"}[rot]
    return Effect(f"E{rot}{carriage}", "angular", "urad/m",
                  f"an angular error motion E{rot}{carriage} (the {carriage} carriage rotating about "
                  f"{about} in proportion to its travel)",
                  "a second probe offset, in another direction, at the same positions (Forbes 2025 "
                  "section 3.3: rotation errors act through the probe offset)")


def _straightness(dev: str, car: str) -> Effect:
    return Effect(f"E{dev}{car}", "straightness", "um",
                  f"a straightness error E{dev}{car} (the {car} carriage deviating along "
                  f"{dev.lower()}, orders 2 and 3 of its travel)",
                  f"records whose {dev.lower()} coordinate is seen at many places along the "
                  f"{car.lower()} travel (a ball plate, or diagonal lengths across it)", vector=True)


def _reversal(ax: str) -> Effect:
    return Effect(f"reversal_{ax}", "reversal", "um",
                  f"a reversal error along {ax} (backlash or pre-travel: points approached along "
                  f"+{ax} shifted by +r, along -{ax} by -r)",
                  f"points approached along {ax} from both sides, and points approached from other "
                  f"directions (a probe radius error moves them too, a reversal along {ax} does not)")


#: the table of docs/recordings.md section 4, in its order (the order decides among exact aliases)
EFFECTS: tuple[Effect, ...] = (
    Effect("scale", "scale", "um/m", "a scale error", "lengths in several directions (ISO 10360-2: seven positions)"),
    Effect("scale_x", "scale_axis", "um/m", "an x-axis scale error", "lengths along other directions than x"),
    Effect("scale_y", "scale_axis", "um/m", "a y-axis scale error", "lengths along other directions than y"),
    Effect("scale_z", "scale_axis", "um/m", "a z-axis scale error", "lengths along other directions than z"),
    Effect("squareness_xy", "squareness", "urad", "a squareness error between x and y", "diagonal lengths in the xy plane"),
    Effect("squareness_xz", "squareness", "urad", "a squareness error between x and z", "diagonal lengths in the xz plane"),
    Effect("squareness_yz", "squareness", "urad", "a squareness error between y and z", "diagonal lengths in the yz plane"),
    Effect("thermal_expansion", "thermal_expansion", "ppm/K", "an expansion-coefficient error of the artefact",
           "records at different artefact temperatures (temperature_C varying)"),
    Effect("probe_radius", "probe_radius", "um", "a probe radius error",
           "both unidirectional and bidirectional probing (normals of both signs)"),
    Effect("probe_qualification", "probe_qualification", "um", "a probe qualification (offset) error",
           "lengths whose ends are probed with different probes, and with the probes swapped", vector=True),
    *(_angular(r, c) for c in "XYZ" for r in "ABC"),
    Effect("scale_drift", "scale_drift", "um/m/h", "a scale drifting in time",
           "records spread in time in an order not tied to length or position (time_s)"),
    Effect("offset_drift", "offset_drift", "um/h", "a drift of every point in time",
           "point records spread in time, repeated positions at different times (time_s)", vector=True),
    # second edition (docs/recordings.md section 7), after the first edition's: among exact
    # aliases the first edition's effect is named
    *(_straightness(d, c) for c in "XYZ" for d in "XYZ" if d != c),
    *(_reversal(ax) for ax in "xyz"),
    Effect("probe_lobing", "probe_lobing", "um", "a probe lobing error (the probe's radius depending on the approach "
           "direction: harmonics 2-4 of the normal's azimuth about the stylus axis)",
           "points probed from many directions around the stylus axis (a circle or sphere with 9 or more "
           "points per probe)", vector=True),
    *(Effect(f"thermal_gradient_{a}", "thermal_gradient", "ppm/K/m",
             f"an expansion-coefficient error of the artefact varying linearly along {a} (a thermal "
             "gradient)",
             f"records at different temperatures spread along {a} (temperature_C varying with position)")
      for a in AXES),
    *(Effect(f"periodic_{a}", "periodic", "um",
             f"a periodic error along {a} (a sine of the {a} travel: ball screw lead, scale grating)",
             f"records sampling the {a} travel densely (a step gauge or a scan along {a}: four or more "
             f"probings per period, three or more periods)", vector=True)
      for a in AXES),
)
BY_NAME = {e.name: e for e in EFFECTS}
NAMES = tuple(e.name for e in EFFECTS)


def _family(family: str) -> tuple[str, ...]:
    return tuple(e.name for e in EFFECTS if e.family == family)


ANGULAR = _family("angular")              # E<R><C>: EAX, EBX, ECX, EAY, ...
STRAIGHTNESS = _family("straightness")    # E<D><C>: EYX, EZX, EXY, ...
REVERSAL = _family("reversal")
GRADIENT = _family("thermal_gradient")
PERIODIC = _family("periodic")
#: plausible pitches of a periodic error (docs/recordings.md section 7), mm
PERIOD_RANGE_MM = (1.0, 200.0)
#: identifiability of a period (docs/diagnose.md section 6): at least this many probings per cycle
#: at the widest gap between the positions seen, and at least this many cycles over the travel
SAMPLES_PER_CYCLE = 4
MIN_CYCLES = 3
#: the scan's frequency step is 1/(PERIOD_OVERSAMPLE x travel): a quarter of the resolution
PERIOD_OVERSAMPLE = 4
#: a normal with |n_xy| below this has no azimuth about the stylus axis (probe_lobing)
LOBING_MIN_XY = 0.1
#: |n_a| above this: the probing moves axis a (reversal effects)
APPROACH_MIN = 0.1
ROT_AXIS = {"A": 0, "B": 1, "C": 2}
CARRIAGE_AXIS = {"X": 0, "Y": 1, "Z": 2}

#: a column whose largest entry is below REL_ZERO times its natural full-scale value is "no
#: sensitivity" (noise-level coordinates of planar or axis-parallel data must not make an effect
#: look identifiable)
REL_ZERO = 1e-4


class NotApplicable(Exception):
    """The records lack what the effect needs (``str`` is the reason for ``not_identifiable``)."""


@dataclass
class Design:
    """What the sensitivities are built from (arrays in mm, °C, s; probe index into probe_ids).

    Length records (``kind == "length"``): per record ``na`` (unit direction), ``U1``/``U2`` (ram
    positions x - p), ``N1``/``N2`` (normals or None), ``k1``/``k2`` (probe index), ``P1``/``P2``
    (offsets), ``ref`` (reference length).  Point records (``kind == "point"``): per record ``Y``
    (nominal point in machine coordinates), ``U`` (= Y - p), ``N``, ``k``, ``P``, centroid ``c``
    and ``dims`` (2 or 3); the residual vector is coordinate-major (x1, y1, [z1,] x2, ...).
    """

    kind: str
    probe_ids: tuple[str, ...]
    offsets_given: bool
    T: np.ndarray | None = None
    t: np.ndarray | None = None
    # length
    na: np.ndarray | None = None
    U1: np.ndarray | None = None
    U2: np.ndarray | None = None
    N1: np.ndarray | None = None
    N2: np.ndarray | None = None
    k1: np.ndarray | None = None
    k2: np.ndarray | None = None
    P1: np.ndarray | None = None
    P2: np.ndarray | None = None
    ref: np.ndarray | None = None
    # point
    Y: np.ndarray | None = None
    U: np.ndarray | None = None
    N: np.ndarray | None = None
    k: np.ndarray | None = None
    P: np.ndarray | None = None
    c: np.ndarray | None = None
    dims: int = 3
    extent_mm: float = field(default=0.0)

    @property
    def n_records(self) -> int:
        return len(self.na) if self.kind == "length" else len(self.Y)

    @property
    def n_obs(self) -> int:
        return self.n_records if self.kind == "length" else self.dims * len(self.Y)

    def point_rows(self, delta: np.ndarray) -> np.ndarray:
        """(m, 3) or (m, 3, q) point displacements -> (dims*m,) or (dims*m, q) rows."""
        d = delta[:, : self.dims]
        return d.reshape(-1) if d.ndim == 2 else d.reshape(-1, d.shape[-1])


@dataclass
class Columns:
    """Sensitivity columns of one candidate: ``X`` (n_obs x q), labels of the q parameters."""

    name: str
    X: np.ndarray
    labels: list[str]
    full_scale: float          # natural size of an entry (for the no-sensitivity test)
    period_mm: float | None = None   # periodic_*: the period the columns are evaluated at


def _varying(v: np.ndarray | None) -> bool:
    return v is not None and float(np.ptp(v)) > 1e-9


def rotation_vector(rot: str, P: np.ndarray) -> np.ndarray:
    """e_R x p for every row of P (mm): the tip displacement per radian of rotation about axis R
    (Forbes 2025 eq. 24: G alpha = alpha x p)."""
    e = np.zeros(3)
    e[ROT_AXIS[rot]] = 1.0
    return np.cross(e, P)


def columns(design: Design, name: str, period_mm: float | None = None) -> Columns:
    """The sensitivity columns of candidate ``name`` for these records (raises NotApplicable);
    ``period_mm``: the period of a ``periodic_*`` candidate (default: the longest the records can
    identify, :func:`period_grid`; the search scans it)."""
    if name not in BY_NAME:
        raise KeyError(name)
    D = design
    if name in PERIODIC:
        return periodic_columns(D, name, period_mm)
    _needs(D, name)
    fam = FAMILIES[BY_NAME[name].family]
    f = fam.length if D.kind == "length" else fam.point
    if f is None:
        raise AssertionError(f"{name}: _needs lets no {D.kind} record through")
    return f(D, name)


def legendre_23(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P_2(s) = (3 s^2 - 1)/2 and P_3(s) = (5 s^3 - 3 s)/2 (straightness, section 7)."""
    return 0.5 * (3.0 * s**2 - 1.0), 0.5 * (5.0 * s**3 - 3.0 * s)


def travel(D: Design, car: str) -> tuple[float, float]:
    """Smallest and largest ram coordinate of carriage ``car`` (X, Y, Z) over every probing."""
    c = CARRIAGE_AXIS[car]
    U = np.vstack([D.U1, D.U2]) if D.kind == "length" else D.U
    return float(np.min(U[:, c])), float(np.max(U[:, c]))


def _travel_s(D: Design, car: str, U: np.ndarray) -> np.ndarray:
    lo, hi = travel(D, car)
    return (2.0 * U[:, CARRIAGE_AXIS[car]] - lo - hi) / (hi - lo)


def approach_sign(N: np.ndarray, a: int) -> np.ndarray:
    """+1 where a probing approaches along +a (outward normal n_a < -APPROACH_MIN), -1 along -a
    (n_a > APPROACH_MIN), 0 where it hardly moves axis a (reversal, section 7)."""
    n = N[:, a]
    return np.where(n < -APPROACH_MIN, 1.0, np.where(n > APPROACH_MIN, -1.0, 0.0))


def azimuth_harmonics(N: np.ndarray) -> dict[str, np.ndarray]:
    """{"c2": cos 2 phi, "s2": sin 2 phi, ..., "s4"} of the azimuth phi of every normal about z, as
    polynomials of (c, s) = (n_x, n_y)/|n_xy|; 0 where |n_xy| <= LOBING_MIN_XY (no azimuth)."""
    rho = np.hypot(N[:, 0], N[:, 1])
    ok = rho > LOBING_MIN_XY
    c = np.where(ok, N[:, 0] / np.where(ok, rho, 1.0), 0.0)
    s = np.where(ok, N[:, 1] / np.where(ok, rho, 1.0), 0.0)
    return {"c2": c**2 - s**2, "s2": 2 * c * s,
            "c3": c**3 - 3 * c * s**2, "s3": 3 * c**2 * s - s**3,
            "c4": c**4 - 6 * c**2 * s**2 + s**4, "s4": 4 * c**3 * s - 4 * c * s**3}


def lobing_labels(D: Design) -> list[str]:
    return [f"{pid}.{h}" for pid in D.probe_ids for h in ("c2", "s2", "c3", "s3", "c4", "s4")]


def positions_seen(D: Design, a: int) -> np.ndarray:
    """The distinct ram coordinates along axis a (mm, sorted, to 1 µm) of the probings that see a
    displacement along a: both ends of every length with |n_a| > APPROACH_MIN, every point (with a
    coordinate a)."""
    if D.kind == "length":
        sees = np.abs(D.na[:, a]) > APPROACH_MIN
        t = np.r_[D.U1[sees, a], D.U2[sees, a]]
    else:
        t = D.U[:, a] if a < D.dims else np.zeros(0)
    return np.unique(np.round(t, 3))


def period_range(D: Design, a: int) -> tuple[float, float, float]:
    """(P_min, P_max, travel) in mm of the periods the records identify along axis a: P_min =
    SAMPLES_PER_CYCLE x the widest gap between the positions seen, P_max = travel/MIN_CYCLES,
    both within PERIOD_RANGE_MM (raises NotApplicable when none is left)."""
    ax = AXES[a]
    t = positions_seen(D, a)
    if len(t) < 2 * SAMPLES_PER_CYCLE:
        raise NotApplicable(f"the records see {ax} at {len(t)} position(s): a period needs the {ax} travel "
                            f"sampled densely ({2 * SAMPLES_PER_CYCLE} or more positions; a step gauge or a "
                            f"scan along {ax})")
    span = float(t[-1] - t[0])
    gap = float(np.max(np.diff(t)))
    lo = max(PERIOD_RANGE_MM[0], SAMPLES_PER_CYCLE * gap)
    hi = min(PERIOD_RANGE_MM[1], span / MIN_CYCLES)
    if lo > hi:
        raise NotApplicable(
            f"the records see {ax} at {len(t)} positions over {span:.0f} mm with gaps up to {gap:.3g} mm: a "
            f"period is identifiable from {SAMPLES_PER_CYCLE} x {gap:.3g} = {SAMPLES_PER_CYCLE * gap:.3g} mm "
            f"({SAMPLES_PER_CYCLE} probings per cycle at the widest gap) to {span:.0f}/{MIN_CYCLES} = "
            f"{span / MIN_CYCLES:.3g} mm ({MIN_CYCLES} cycles over the travel), within "
            f"{PERIOD_RANGE_MM[0]:g}-{PERIOD_RANGE_MM[1]:g} mm: none; a step gauge or a scan along {ax} "
            f"samples it densely")
    return lo, hi, span


def period_grid(D: Design, a: int) -> tuple[np.ndarray, int]:
    """The periods scanned along axis a (mm, longest first: equally spaced in frequency 1/P with
    step 1/(PERIOD_OVERSAMPLE x travel), a quarter of the resolution 1/travel) and the
    look-elsewhere factor M: Bonferroni over the periods of the grid, M = their number.  (One per
    resolution, 1 + (1/P_min - 1/P_max) x travel, is too few: on null step gauges and hole plates
    the best period's p-value fell below 0.01 in 1.5-3.5 % of the sets; with the grid's count in
    0-1 %, docs/diagnose.md section 6.)"""
    lo, hi, span = period_range(D, a)
    f0, f1 = 1.0 / hi, 1.0 / lo
    k = max(1, int(math.ceil((f1 - f0) * span * PERIOD_OVERSAMPLE)))
    f = np.linspace(f0, f1, k + 1)
    return 1.0 / f, len(f)


def periodic_angle(D: Design, a: int, u: np.ndarray, period_mm: float) -> np.ndarray:
    """The phase w = 2 pi t/P of ram coordinates ``u`` along axis a, t = u - (lo + hi)/2 about the
    middle of the travel (:func:`travel`): the one definition the columns, the period's column and
    the plot of a fitted periodic error share."""
    lo, hi = travel(D, AXES[a].upper())
    return 2.0 * math.pi * (u - 0.5 * (lo + hi)) / period_mm


def periodic_columns(D: Design, name: str, period_mm: float | None = None) -> Columns:
    """Columns (a, b) of ``periodic_<axis>`` at period ``period_mm`` (default: the longest
    identifiable); the labels are "a", "b" (µm)."""
    a = AXES.index(name[-1])
    if period_mm is None:
        period_mm = float(period_grid(D, a)[0][0])
    elif not (math.isfinite(period_mm) and period_mm > 0):
        raise NotApplicable(f"the period must be a positive number of mm, got {period_mm!r}")
    if D.kind == "length":
        w1, w2 = (periodic_angle(D, a, U[:, a], period_mm) for U in (D.U1, D.U2))
        X = D.na[:, a, None] * np.column_stack([np.sin(w2) - np.sin(w1), np.cos(w2) - np.cos(w1)])
    else:
        w = periodic_angle(D, a, D.U[:, a], period_mm)
        X = np.column_stack([D.point_rows(_on_axis(len(D.Y), a, f(w))) for f in (np.sin, np.cos)])
    return Columns(name, X, ["a", "b"], 1.0, period_mm=float(period_mm))


def period_column(D: Design, name: str, period_mm: float, a_um: float, b_um: float) -> np.ndarray:
    """The sensitivity to the period (µm per mm) of ``periodic_<axis>`` at (a, b, P): the partial
    derivative of a sin(2 pi t/P) + b cos(2 pi t/P), (a cos - b sin)(-2 pi t/P^2).  Added to the
    refit (linearized at the fit with P fixed) so that the uncertainties of a and b include that of
    the period, and the period gets its own (docs/diagnose.md section 6)."""
    a = AXES.index(name[-1])

    def d_dP(U: np.ndarray) -> np.ndarray:
        w = periodic_angle(D, a, U[:, a], period_mm)
        return (a_um * np.cos(w) - b_um * np.sin(w)) * (-w / period_mm)

    if D.kind == "length":
        return D.na[:, a] * (d_dP(D.U2) - d_dP(D.U1))
    return D.point_rows(_on_axis(len(D.Y), a, d_dP(D.U)))


def _on_axis(m: int, a: int, w: np.ndarray) -> np.ndarray:
    d = np.zeros((m, 3))
    d[:, a] = w
    return d


#: the smallest travel (mm) over which a straightness is fitted
MIN_TRAVEL_MM = 1.0


def _needs_temperatures(D: Design, looks_like: str, separate: str) -> None:
    if D.T is None:
        raise NotApplicable("needs temperature_C (absent from the records)")
    if not _varying(D.T):
        raise NotApplicable(f"temperature_C is the same for every record: {looks_like}; records at "
                            f"different temperatures{separate} separate them")


def _needs_normals(D: Design, why: str) -> np.ndarray:
    """Every probing's normal (lengths: both ends stacked), or NotApplicable saying ``why``."""
    if (D.N1 if D.kind == "length" else D.N) is None:
        raise NotApplicable("needs normals (" + ("n1x..n2z" if D.kind == "length" else "nx,ny,nz")
                            + f") {why}")
    return np.vstack([D.N1, D.N2]) if D.kind == "length" else D.N


def _needs(D: Design, name: str) -> None:
    if name == "thermal_expansion":
        _needs_temperatures(D, "an expansion error then looks exactly like a scale error", "")
    if name == "probe_radius":
        _needs_normals(D, "to know the direction in which a radius error moves each point")
    if name == "probe_qualification" and len(D.probe_ids) < 2:
        raise NotApplicable("needs two or more probes (one probe: its offset error cancels or is "
                            "absorbed)")
    if name in ANGULAR:
        P = np.vstack([D.P1, D.P2]) if D.kind == "length" else D.P
        if not D.offsets_given or not np.any(P):
            raise NotApplicable("needs probe offsets (p1x..p2z, px..pz or [[probes]] offset_mm): an "
                                "angular error motion moves the stylus tip through the probe offset "
                                "only (Forbes 2025 eq. 24)")
    if name in STRAIGHTNESS:
        lo, hi = travel(D, name[2])
        if hi - lo < MIN_TRAVEL_MM:
            raise NotApplicable(f"the {name[2]} carriage moves {hi - lo:.3g} mm across these records: "
                                f"no travel to see a straightness along (at least {MIN_TRAVEL_MM:g} mm)")
    if name == "probe_lobing":
        N = _needs_normals(D, "to know the approach direction of each point")
        if not np.any(np.hypot(N[:, 0], N[:, 1]) > LOBING_MIN_XY):
            raise NotApplicable("every normal is along the stylus axis (z): no approach direction "
                                "around it to see a lobing")
    if name in GRADIENT:
        _needs_temperatures(D, "a gradient of the expansion coefficient then looks like a curved scale "
                               "error", " spread along the axis")
    if name in REVERSAL:
        a = AXES.index(name[-1])
        w = approach_sign(_needs_normals(D, "to know from which side each point was approached"), a)
        if not (np.any(w > 0) and np.any(w < 0)):
            raise NotApplicable(f"needs points approached along {name[-1]} from both sides (normals with "
                                f"n{name[-1]} above {APPROACH_MIN:g} and below -{APPROACH_MIN:g}): from "
                                "one side a reversal error is a constant the alignment absorbs")
    if name in ("scale_drift", "offset_drift"):
        if name == "offset_drift" and D.kind == "length":
            raise NotApplicable("needs point records with time_s: a drift of every point cancels in a "
                                "length between two points probed at one time")
        if D.t is None:
            raise NotApplicable("needs time_s (absent from the records)")
        if not _varying(D.t):
            raise NotApplicable("time_s is the same for every record: a drift is then a constant "
                                "error; records spread in time separate them")


# -- the sensitivity columns per family: one function for length records, one for point records --

def _ndu(D: Design) -> np.ndarray:
    """n_a . (u2 - u1) of every length record (mm)."""
    return np.einsum("ij,ij->i", D.na, D.U2 - D.U1)


def _unit_axis(D: Design, a: int, weight: np.ndarray) -> np.ndarray:
    """Point rows of a displacement ``weight`` along axis a."""
    d = np.zeros((len(D.Y), 3))
    d[:, a] = weight
    return D.point_rows(d)


def _scale_length(D: Design, name: str) -> Columns:
    return Columns(name, (MILLI * _ndu(D))[:, None], [name], MILLI * D.extent_mm)


def _scale_point(D: Design, name: str) -> Columns:
    return Columns(name, D.point_rows(MILLI * (D.U - D.c))[:, None], [name], MILLI * D.extent_mm)


def _scale_axis_length(D: Design, name: str) -> Columns:
    a = AXES.index(name[-1])
    du = D.U2 - D.U1
    return Columns(name, (MILLI * D.na[:, a] * du[:, a])[:, None], [name], MILLI * D.extent_mm)


def _scale_axis_point(D: Design, name: str) -> Columns:
    a = AXES.index(name[-1])
    R = D.U - D.c
    return Columns(name, _unit_axis(D, a, MILLI * R[:, a])[:, None], [name], MILLI * D.extent_mm)


def _squareness_length(D: Design, name: str) -> Columns:
    a, b = AXES.index(name[-2]), AXES.index(name[-1])   # x' = x + b_xy y: moves a by u_b
    du = D.U2 - D.U1
    return Columns(name, (MILLI * D.na[:, a] * du[:, b])[:, None], [name], MILLI * D.extent_mm)


def _squareness_point(D: Design, name: str) -> Columns:
    a, b = AXES.index(name[-2]), AXES.index(name[-1])
    R = D.U - D.c
    return Columns(name, _unit_axis(D, a, MILLI * R[:, b])[:, None], [name], MILLI * D.extent_mm)


def _thermal_expansion_length(D: Design, name: str) -> Columns:
    dT = D.T - T_REF_C
    return Columns(name, (MILLI * dT * D.ref)[:, None], [name],
                   MILLI * float(np.max(np.abs(dT))) * float(np.max(D.ref)))


def _thermal_expansion_point(D: Design, name: str) -> Columns:
    dT = D.T - T_REF_C
    return Columns(name, D.point_rows(MILLI * dT[:, None] * (D.Y - D.c))[:, None], [name],
                   MILLI * float(np.max(np.abs(dT))) * D.extent_mm)


def _probe_radius_length(D: Design, name: str) -> Columns:
    col = np.einsum("ij,ij->i", D.na, D.N2) - np.einsum("ij,ij->i", D.na, D.N1)
    return Columns(name, col[:, None], [name], 1.0)


def _probe_radius_point(D: Design, name: str) -> Columns:
    return Columns(name, D.point_rows(D.N)[:, None], [name], 1.0)


def _probe_qualification_length(D: Design, name: str) -> Columns:
    cols, labels = [], []
    for k in range(1, len(D.probe_ids)):
        w = (D.k2 == k).astype(float) - (D.k1 == k).astype(float)
        for a in range(3):
            cols.append(D.na[:, a] * w)
            labels.append(f"{D.probe_ids[k]}.d{AXES[a]}")
    return Columns(name, np.column_stack(cols), labels, 1.0)


def _probe_qualification_point(D: Design, name: str) -> Columns:
    cols, labels = [], []
    for k in range(1, len(D.probe_ids)):
        for a in range(3):
            cols.append(_unit_axis(D, a, (D.k == k).astype(float)))
            labels.append(f"{D.probe_ids[k]}.d{AXES[a]}")
    return Columns(name, np.column_stack(cols), labels, 1.0)


def _angular_length(D: Design, name: str) -> Columns:
    rot, ax = name[1], CARRIAGE_AXIS[name[2]]
    na = D.na
    v1, v2 = rotation_vector(rot, D.P1), rotation_vector(rot, D.P2)
    col = MICRO * (D.U2[:, ax] * np.einsum("ij,ij->i", na, v2) - D.U1[:, ax] * np.einsum("ij,ij->i", na, v1))
    umax = float(np.max(np.abs(np.vstack([D.U1, D.U2]))))
    pmax = float(np.max(np.linalg.norm(np.vstack([D.P1, D.P2]), axis=1)))
    return Columns(name, col[:, None], [name], MICRO * umax * pmax)


def _angular_point(D: Design, name: str) -> Columns:
    rot, ax = name[1], CARRIAGE_AXIS[name[2]]
    v = rotation_vector(rot, D.P)
    col = D.point_rows(MICRO * D.U[:, ax][:, None] * v)
    umax = float(np.max(np.abs(D.U)))
    pmax = float(np.max(np.linalg.norm(D.P, axis=1)))
    return Columns(name, col[:, None], [name], MICRO * umax * pmax)


def _scale_drift_length(D: Design, name: str) -> Columns:
    h = D.t / 3600.0
    return Columns(name, (MILLI * h * _ndu(D))[:, None], [name],
                   MILLI * float(np.max(np.abs(h))) * D.extent_mm)


def _scale_drift_point(D: Design, name: str) -> Columns:
    h = D.t / 3600.0
    return Columns(name, D.point_rows(MILLI * h[:, None] * (D.U - D.c))[:, None], [name],
                   MILLI * float(np.max(np.abs(h))) * D.extent_mm)


def _offset_drift_point(D: Design, name: str) -> Columns:
    h = D.t / 3600.0
    cols = [_unit_axis(D, a, h) for a in range(3)]
    return Columns(name, np.column_stack(cols), [f"v{AXES[a]}" for a in range(3)],
                   float(np.max(np.abs(h))))


def _straightness_length(D: Design, name: str) -> Columns:
    d = AXES.index(name[1].lower())
    P1 = legendre_23(_travel_s(D, name[2], D.U1))
    P2 = legendre_23(_travel_s(D, name[2], D.U2))
    cols = [D.na[:, d] * (b - a) for a, b in zip(P1, P2)]
    return Columns(name, np.column_stack(cols), ["c2", "c3"], 1.0)


def _straightness_point(D: Design, name: str) -> Columns:
    d = AXES.index(name[1].lower())
    cols = [_unit_axis(D, d, Pk) for Pk in legendre_23(_travel_s(D, name[2], D.U))]
    return Columns(name, np.column_stack(cols), ["c2", "c3"], 1.0)


def _reversal_length(D: Design, name: str) -> Columns:
    a = AXES.index(name[-1])
    w = approach_sign(D.N2, a) - approach_sign(D.N1, a)
    return Columns(name, (D.na[:, a] * w)[:, None], [name], 1.0)


def _reversal_point(D: Design, name: str) -> Columns:
    a = AXES.index(name[-1])
    return Columns(name, _unit_axis(D, a, approach_sign(D.N, a))[:, None], [name], 1.0)


def _probe_lobing_length(D: Design, name: str) -> Columns:
    H1, H2 = azimuth_harmonics(D.N1), azimuth_harmonics(D.N2)
    n1, n2 = np.einsum("ij,ij->i", D.na, D.N1), np.einsum("ij,ij->i", D.na, D.N2)
    cols = [n2 * H2[h] * (D.k2 == k) - n1 * H1[h] * (D.k1 == k)
            for k in range(len(D.probe_ids)) for h in ("c2", "s2", "c3", "s3", "c4", "s4")]
    return Columns(name, np.column_stack(cols), lobing_labels(D), 1.0)


def _probe_lobing_point(D: Design, name: str) -> Columns:
    H = azimuth_harmonics(D.N)
    cols = [D.point_rows(D.N * (H[h] * (D.k == k))[:, None])
            for k in range(len(D.probe_ids)) for h in ("c2", "s2", "c3", "s3", "c4", "s4")]
    return Columns(name, np.column_stack(cols), lobing_labels(D), 1.0)


def _thermal_gradient_length(D: Design, name: str) -> Columns:
    a = AXES.index(name[-1])
    X1, X2 = D.U1 + D.P1, D.U2 + D.P2
    xa = np.r_[X1[:, a], X2[:, a]]
    mid = 0.5 * (X1[:, a] + X2[:, a]) - 0.5 * (xa.min() + xa.max())
    dT = D.T - T_REF_C
    L = D.extent_mm
    return Columns(name, (MILLI * MILLI * dT * D.ref * mid)[:, None], [name],
                   MILLI * MILLI * float(np.max(np.abs(dT))) * L * L)


def _thermal_gradient_point(D: Design, name: str) -> Columns:
    a = AXES.index(name[-1])
    dT = D.T - T_REF_C
    rel = D.Y - D.c
    L = D.extent_mm
    return Columns(name, D.point_rows(MILLI * MILLI * (dT * rel[:, a])[:, None] * rel)[:, None], [name],
                   MILLI * MILLI * float(np.max(np.abs(dT))) * L * L)


@dataclass(frozen=True)
class Sensitivity:
    """How one family of effects moves the records: its columns for length records (None: not
    applicable to lengths) and for point records, functions (Design, name) -> Columns."""

    length: Callable[[Design, str], Columns] | None
    point: Callable[[Design, str], Columns]


#: the sensitivity columns of every family of :data:`EFFECTS` (``Effect.family``); the workbook's
#: formulas of the same families are ``generator.diagnosis.formulas.FORMULAS``, and
#: tests/diagnosis/test_diagnose_effect_formulas.py compares the two cell by cell for every effect
FAMILIES: dict[str, Sensitivity] = {
    "scale": Sensitivity(_scale_length, _scale_point),
    "scale_axis": Sensitivity(_scale_axis_length, _scale_axis_point),
    "squareness": Sensitivity(_squareness_length, _squareness_point),
    "thermal_expansion": Sensitivity(_thermal_expansion_length, _thermal_expansion_point),
    "probe_radius": Sensitivity(_probe_radius_length, _probe_radius_point),
    "probe_qualification": Sensitivity(_probe_qualification_length, _probe_qualification_point),
    "angular": Sensitivity(_angular_length, _angular_point),
    "scale_drift": Sensitivity(_scale_drift_length, _scale_drift_point),
    "offset_drift": Sensitivity(None, _offset_drift_point),
    "straightness": Sensitivity(_straightness_length, _straightness_point),
    "reversal": Sensitivity(_reversal_length, _reversal_point),
    "probe_lobing": Sensitivity(_probe_lobing_length, _probe_lobing_point),
    "thermal_gradient": Sensitivity(_thermal_gradient_length, _thermal_gradient_point),
    "periodic": Sensitivity(periodic_columns, periodic_columns),   # at a period: see columns()
}


def alignment_columns(D: Design) -> tuple[np.ndarray, list[str]]:
    """Rigid-body alignment of point records (baseline nuisance, docs/recordings.md section 1b): translations
    (µm) and small rotations (µrad) about the centroid, delta = t + 1e-3 omega x (y - c).
    2-D data: t_x, t_y and the rotation about z."""
    m = len(D.Y)
    r = D.Y - D.c
    cols, labels = [], []
    axes = range(D.dims)
    for a in axes:
        d = np.zeros((m, 3))
        d[:, a] = 1.0
        cols.append(D.point_rows(d))
        labels.append(f"t{AXES[a]}_um")
    rots = (2,) if D.dims == 2 else (0, 1, 2)
    for a in rots:
        e = np.zeros(3)
        e[a] = 1.0
        cols.append(D.point_rows(MILLI * np.cross(e, r)))
        labels.append(f"w{AXES[a]}_urad")
    return np.column_stack(cols), labels
