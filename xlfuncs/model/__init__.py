"""The six-factor point-cloud model of Forbes 2025, and the workpiece's factor W, in one place.

* :mod:`.hyperparameters` -- one record per hyper-parameter and per factor, the tables derived;
* :mod:`.workpiece` -- :class:`Workpiece`, the part's thermal state (factor W, docs/workpiece.md);
* :mod:`.parameters` -- ``FACTORS``, :class:`Parameters`, :class:`Probe`, :class:`PointCloud`;
* :mod:`.scenarios` -- the MPE statements and hyper-parameters of Table 3 (``MPE1``, ``MPE2``);
* :mod:`.geometry` -- squared distances, G_k (eq. 24), G(u) (eq. 11), the rank-7 length rows;
* :mod:`.factors` -- the factor covariances of eq. (28) and W, block and diagonal form.

The evaluation paths built on them: :mod:`xlfuncs.pointcloud` (dense V_X, distances),
:mod:`xlfuncs.blocked` (blocks, V_A, length records), :mod:`xlfuncs.lowrank`,
:mod:`xlfuncs.montecarlo`, :mod:`xlfuncs.locator.structured`,
:mod:`xlfuncs.locator.structured_lengths`, :mod:`xlfuncs.locator.simulate`,
:mod:`xlfuncs.locator.model`.
"""

from .factors import (
                      V_S_diag_um_per_mm2,
                      check_factors,
                      factor_block,
                      factor_diagonal,
                      gauss_kernel,
                      point_index,
                      probe_arrays,
                      workpiece_columns,
)
from .geometry import G_S, scale_rows, skew, sq_dists
from .hyperparameters import MACHINE_FACTORS
from .parameters import FACTORS, MAX_PARAMETER, MILLI, MIN_LENGTH_SCALE, Parameters, PointCloud, Probe
from .scenarios import MPE1, MPE2, TABLE3, Scenario
from .workpiece import MATERIALS, REFERENCE_C, Workpiece, workpiece_from_readings

__all__ = ["FACTORS", "MAX_PARAMETER", "MILLI", "MIN_LENGTH_SCALE", "Parameters", "Probe", "PointCloud",
           "MPE1", "MPE2", "TABLE3", "Scenario", "sq_dists", "skew", "G_S", "scale_rows",
           "V_S_diag_um_per_mm2", "probe_arrays", "gauss_kernel", "point_index", "check_factors", "factor_block",
           "factor_diagonal", "workpiece_columns", "MACHINE_FACTORS", "Workpiece", "MATERIALS", "REFERENCE_C",
           "workpiece_from_readings"]
