"""Characteristics of a drawing from several least-squares features fitted in one task, with
their uncertainty under the full point-cloud variance V_X of one CMM (Forbes 2025 eq. (28)).

Features (Forbes 2022): every feature is fitted to its own points of one joint point set;
stacking their sensitivity matrices G_A|X (eq. (8)) row-wise gives the joint

    G = [G_1 (columns of the points of feature 1); G_2; ...]   (sum n_f) x 3m,
    V_A = G V_X G^T                                            (Forbes 2025 section 5.6),

whose off-diagonal blocks are the correlations between features measured by one CMM (scale,
squareness, the spatially correlated errors, a probe qualification shared by all points).

Characteristics (ISO 1101:2017 / ASME Y14.5-2018 names) are functions of the features' local
parameters a and, for form and for orientation zones of surfaces, of the extreme points
directly.  Each is linearised as

    delta c = s_A delta a + s_Xd delta x   ->   s_X = s_Xd + s_A G,   u^2(c) = s_X V_X s_X^T,

s_A by central differences through the features' geometry (xlfuncs.features.update_frame),
s_Xd over the coordinates of the points that decide the value (the contact points of a minimum
zone, the highest and lowest point of a peak-to-valley) with those points held fixed.  For the
smooth characteristics (size, distance, angle, orientation and position of axes) s_Xd = 0 and
u^2 = s_A V_A s_A^T -- the workbook's live MMULT.  Form values and zones of surfaces are maxima
over points: their u is the active-set linearisation; the Monte Carlo (:func:`monte_carlo`)
says how good it is.

Conventions (docs/characteristics.md): lengths in mm, angles in degrees; u in µm (lengths) or
µrad (angles).  The size of a feature of size is its least-squares diameter (not the ASME
actual mating envelope); position and axis orientation are evaluated at the ends of the axis
over the extent of the feature's points along the datum axis at the reference.

One job per module: :mod:`.specs` the features, frames and characteristics as the task gives
them; :mod:`.joint` the joint fit and V_A; :mod:`.evaluation` values, sensitivities and u;
:mod:`.mcm` the Monte Carlo check.  The names the rest of the project uses are re-exported here.
"""

from .evaluation import Context, Result, evaluate, propagate
from .joint import JointFit, fit_features, joint_V_A
from .mcm import monte_carlo
from .specs import (
                    FORM_TYPES,
                    ORIENTATION_TYPES,
                    SIZE_TYPES,
                    SMOOTH_TYPES,
                    TYPES,
                    CharacteristicSpec,
                    FeatureSpec,
                    FrameSpec,
)

__all__ = [
    "FeatureSpec", "FrameSpec", "CharacteristicSpec", "JointFit", "Result", "TYPES",
    "fit_features", "joint_V_A", "evaluate", "monte_carlo", "FORM_TYPES", "SMOOTH_TYPES",
    "ORIENTATION_TYPES", "SIZE_TYPES", "Context", "propagate",
]
