"""The specifications of a drawing's characteristics: the features fitted in one task, the datum
reference frames and the characteristics (ISO 1101:2017 / ASME Y14.5-2018 names) with their
tolerances, as the task file gives them (docs/characteristics.md)."""

from __future__ import annotations

from dataclasses import dataclass

FORM_TYPES = ("flatness", "straightness", "roundness", "cylindricity")
ORIENTATION_TYPES = ("perpendicularity", "parallelism", "angularity")
SIZE_TYPES = ("diameter", "width", "cone_angle")
TYPES = SIZE_TYPES + ("distance", "angle") + FORM_TYPES + ORIENTATION_TYPES + ("position",)
#: the types whose value is a smooth function of the features' parameters only
SMOOTH_TYPES = SIZE_TYPES + ("distance", "angle", "position")


# ------------------------------------------------------------------------------------------
# specifications
# ------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FeatureSpec:
    """A feature: ``element`` fitted to the points ``indices`` of the joint point set."""

    name: str
    element: str
    indices: tuple[int, ...]
    circle_plane: str | None = "xy"
    axis_hint: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class FrameSpec:
    """A datum reference frame A|B|C: feature names in order of precedence."""

    name: str
    primary: str
    secondary: str | None = None
    tertiary: str | None = None


@dataclass(frozen=True)
class CharacteristicSpec:
    """A characteristic of the drawing.

    ``type``: diameter (circle, cylinder, sphere), width (two planes), cone_angle (a cone's
    included angle 2 phi, deg), distance (locating point
    of the second feature to the first element), angle (between the two fitted directions --
    normals outward, axes as oriented -- 0 to 180 deg),
    flatness/straightness/roundness/cylindricity (``method`` "LS" peak-to-valley of the
    residuals to the least-squares feature, or "MZ" minimum zone), perpendicularity/parallelism/
    angularity (to the primary datum of ``frame``, or to the feature ``datum``; a plane's zone
    oriented by its least-squares normal, or with ``method`` "MZ" turned about the datum
    direction to its minimum; ``zone``
    "planar" for a surface, "diametral" for an axis; angularity's ``nominal`` angle in deg),
    position (of an axis or centre in ``frame``, at ``nominal_position_mm`` in frame
    coordinates, diametral zone; ``material_condition`` MMC/LMC with the bonus from the size
    characteristic ``size``; ``internal`` for a hole).
    ``direction``: straightness only, the zone direction (the surface's nominal normal).
    Tolerances are carried here, not decided (the build decides them: generator.decision):
    ``lsl``/``usl`` (size, distance, angle) or ``tolerance_mm`` (zone width of form,
    orientation, position).
    ``measured``: the value as measured elsewhere (a QIF results file's, in mm or deg): it is the
    result's value (and a size's value gives the bonus), while the task's points give only the
    sensitivities and so u -- the points of a stand-in part (generator/importers/qif_simulation.py).
    """

    name: str
    type: str
    features: tuple[str, ...]
    method: str = "LS"
    frame: str | None = None
    datum: str | None = None
    nominal: float | None = None
    nominal_position_mm: tuple[float, ...] | None = None
    zone: str = "planar"
    material_condition: str = "RFS"
    size: str | None = None
    internal: bool = True
    direction: tuple[float, float, float] | None = None
    lsl: float | None = None
    usl: float | None = None
    tolerance_mm: float | None = None
    measured: float | None = None
