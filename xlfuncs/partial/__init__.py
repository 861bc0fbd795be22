"""Planning without data (Forbes 2022, sections 4-9), one job per module:
:mod:`.approximations` the analytic approximations H, V, s of partial features (the paper's
Tables 1-8), :mod:`.sampling` the sampling strategies that build the nominal points of a feature
task.  The names the rest of the project uses are re-exported here."""

from .approximations import (
                             Approximation,
                             circle_arc,
                             cone_patch,
                             cone_patch_quadrature,
                             cylinder_patch,
                             line_segment,
                             plane_rectangle,
                             sphere_band,
                             sphere_cap,
                             sphere_full,
                             sphere_patch,
                             sphere_segment,
)
from .sampling import PATTERNS, Sampling, approximation, frame_from_axis, sample

__all__ = [
    "Approximation", "Sampling", "circle_arc", "sphere_patch", "sphere_cap", "sphere_band",
    "sphere_segment", "plane_rectangle", "cylinder_patch", "cone_patch", "line_segment",
    "sphere_full", "PATTERNS", "approximation", "sample", "frame_from_axis", "cone_patch_quadrature",
]
