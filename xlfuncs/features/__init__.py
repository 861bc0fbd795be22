"""Least-squares fitted features and their sensitivities (Forbes 2022), propagated from the
point-cloud variance matrix V_X of Forbes 2025 per influence factor (Forbes 2025, section 5.6).

Fits (Forbes 2022 section 3): orthogonal distance regression, minimise sum_i w_i^2 d_i^2
(eqs. (7), (11)) by Gauss-Newton in the stable parametrisation of the paper: each iteration
moves the data into the frame in which the current element is in standard position (axis
along z, locating point at the origin) and solves for small changes of the local parameters

=========  ===========================================================  =========
element    local parameters (paper's order)                             residuals
=========  ===========================================================  =========
line       x_A_mm, y_A_mm, rot_x_rad, rot_y_rad                         2 / point
plane      z_A_mm, rot_x_rad, rot_y_rad                                 1 / point
circle     x0_mm, y0_mm, r0_mm (in a coordinate plane, section 4)       1 / point
circle     x_A_mm, y_A_mm, z_A_mm, rot_x_rad, rot_y_rad, r0_mm (space)  2 / point
sphere     x0_mm, y0_mm, z0_mm, r0_mm                                   1 / point
cylinder   x_A_mm, y_A_mm, rot_x_rad, rot_y_rad, r0_mm                  1 / point
cone       x_A_mm, y_A_mm, rot_x_rad, rot_y_rad, r0_mm, phi_rad         1 / point
=========  ===========================================================  =========

rot_x, rot_y are small rotations of the axis about the frame's x and y axes (axis direction
R_y(rot_y) R_x(rot_x) e_z ~ (rot_y, -rot_x, 1)); they are the u_A, v_A of the paper's
Jacobians in sections 7 and 8 (docs/errata.md).  The line and the circle in space have two
residuals per point (offsets along two normals); the sum of their squares is the squared
orthogonal distance.

At the solution the sensitivity matrix is (eqs. (8), (12))

    G_A|X = G_A|D N^T,   G_A|D = -(J^T W J)^{-1} J^T W,   W = diag(w_i^2),

with N the 3m x (k m) block-diagonal matrix of the fitted surface normals, and for any V_X

    V_A = G_A|X V_X G_A|X^T,     V_A = sum_f G_A|X V_X,f G_A|X^T   (Forbes 2025 sec. 5.6).

Reported parameters ("global"): the fitted element in machine coordinates -- locating point
(for axes and planes the point of the axis/plane nearest to the centroid of the points),
unit direction/normal components, radius, cone angle -- with covariance T V_A T^T, where T
is the linear map from the local parameters to the global ones.  Along the axis the locating
point is a convention, not a measurement: its uncertainty is that of the axis' intersection
with the plane through x_A orthogonal to the axis, and a direction vector's covariance is
singular along the direction itself.

Units: coordinates and lengths in mm, angles in rad, V_X in µm^2 as produced by
:func:`xlfuncs.pointcloud.V_X_components`; covariances of the parameters in their own units
(mm^2, mm*rad, rad^2), i.e. V_X is converted with 1 µm^2 = 1e-6 mm^2.

One job per module: :mod:`.models` the elements in standard position and their parameter
updates; :mod:`.fitting` the fit and G_A|X; :mod:`.propagation` V_A per factor.  The names the
rest of the project uses are re-exported here.
"""

from .fitting import G_A_X, FeatureFit, fit
from .models import CIRCLE_PLANES, ELEMENTS, MIN_POINTS, local_model, rot_xy_batch, update_frame, update_one
from .propagation import UM2_TO_MM2, FeatureUncertainty, propagate

__all__ = [
    "ELEMENTS", "MIN_POINTS", "FeatureFit", "FeatureUncertainty", "fit", "propagate",
    "G_A_X", "local_model", "UM2_TO_MM2", "update_frame", "rot_xy_batch", "CIRCLE_PLANES", "update_one",
]
