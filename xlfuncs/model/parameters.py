"""The statistical model of Forbes 2025 section 2.4 and Tables 1, 3: the six influence factors,
their hyper-parameters, the probes and the measured point cloud.

Units: coordinates, offsets and distances in mm; uncertainties in µm, variances in µm².
Scale and squareness hyper-parameters are in ppm (1e-6), rotations in µrad, so that
``ppm * mm = 1e-3 µm`` and ``µrad * mm = 1e-3 µm``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import ModelError
from .hyperparameters import FACTORS, MACHINE_SIGMAS, PARTNER, PROBE_OVERRIDES
from .workpiece import Workpiece

__all__ = ["FACTORS", "MILLI", "MAX_PARAMETER", "MIN_LENGTH_SCALE", "Parameters", "Probe", "PointCloud"]

#: conversion of ppm*mm (or µrad*mm) to µm
MILLI = 1e-3


#: largest value any hyper-parameter may take (µm, ppm, µrad, mm); squares stay far from overflow
MAX_PARAMETER = 1e9
#: smallest length scale of a switched-on GP; exp(-d^2/lambda^2) stays well defined
MIN_LENGTH_SCALE = 1e-6


def _check_length_scale(lam_name: str, lam: float, sigma_name: str, sigma: float) -> None:
    if sigma > 0 and lam < MIN_LENGTH_SCALE:
        raise ModelError(f"{lam_name} must be at least {MIN_LENGTH_SCALE:g} when {sigma_name} > 0, got {lam!r}")


@dataclass(frozen=True)
class Parameters:
    """Statistical hyper-parameters of Forbes 2025, Tables 1 and 3 (task-file names and units).

    One field per record of :data:`xlfuncs.model.hyperparameters.HYPERPARAMETERS`, in its order
    (checked by ``tests/core/test_hyperparameters.py``); those with ``per_probe`` are defaults that a
    probe may override.
    """

    sigma_R_um: float = 0.0
    sigma_S_ppm: float = 0.0
    sigma_Sa_ppm: float = 0.0
    sigma_Q_ppm: float = 0.0
    sigma_PQ_um: float = 0.0
    sigma_ET_um: float = 0.0
    lambda_ET_mm: float = 0.0
    sigma_ER_urad: float = 0.0
    lambda_ER_mm: float = 0.0
    sigma_P0_um: float = 0.0
    sigma_P_um: float = 0.0
    lambda_P: float = 0.0
    u_alpha_ppm_per_K: float = 0.0
    u_T_K: float = 0.0

    #: names of the machine's standard-deviation parameters, rescaled by C_max (section 6.8)
    SIGMAS = MACHINE_SIGMAS

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ModelError(f"{name} must be a finite number, got {value!r}")
            if value < 0:
                raise ModelError(f"{name} must not be negative, got {value!r}")
            if value > MAX_PARAMETER:
                raise ModelError(f"{name} = {value!r} is beyond any CMM (at most {MAX_PARAMETER:g})")
        for lam, sigma in PARTNER.items():
            _check_length_scale(lam, getattr(self, lam), sigma, getattr(self, sigma))

    def scaled(self, factor: float) -> "Parameters":
        """All standard deviations divided by ``factor`` (section 6.8: divide by C_max)."""
        return replace(self, **{n: getattr(self, n) / factor for n in self.SIGMAS})


@dataclass(frozen=True)
class Probe:
    """A probe (stylus) configuration: offset p_k and its per-probe uncertainty parameters.

    ``None`` for a sigma means: use the task-wide value of :class:`Parameters`.
    """

    id: str
    offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sigma_PQ_um: float | None = None
    sigma_P0_um: float | None = None
    sigma_P_um: float | None = None
    lambda_P: float | None = None

    def resolved(self, params: Parameters) -> "Probe":
        """A copy with every ``None`` replaced by the task-wide default."""
        vals = {n: getattr(params, n) if getattr(self, n) is None else getattr(self, n)
                for n in PROBE_OVERRIDES}
        for n, v in vals.items():
            if not math.isfinite(v) or v < 0 or v > MAX_PARAMETER:
                raise ModelError(f"probe {self.id}: {n} must be a finite number from 0 to {MAX_PARAMETER:g}")
        for lam, sigma in PARTNER.items():
            if lam in vals:
                _check_length_scale(f"probe {self.id}: {lam}", vals[lam], sigma, vals[sigma])
        return replace(self, **vals)


@dataclass(frozen=True)
class PointCloud:
    """Measured points x_i (mm), outward unit normals n_i and the probe used for each point.

    ``probe_index[i]`` indexes ``probes``.  ``labels`` are the point ids.  ``workpiece``: the part's
    thermal state (the factor W, :mod:`xlfuncs.model.workpiece`; None: no W), ``temperature_C``
    the temperature at each point's probing (records of a calibration; None: the part's T).
    """

    X_mm: np.ndarray
    N: np.ndarray
    probe_index: np.ndarray
    probes: tuple[Probe, ...]
    labels: tuple[str, ...] = field(default=())
    workpiece: Workpiece | None = None
    temperature_C: np.ndarray | None = None

    def __post_init__(self) -> None:
        X = np.asarray(self.X_mm, dtype=float)
        N = np.asarray(self.N, dtype=float)
        k = np.asarray(self.probe_index, dtype=int)
        if X.ndim != 2 or X.shape[1] != 3:
            raise ModelError("points must be an m x 3 array of coordinates in mm")
        if N.shape != X.shape:
            raise ModelError("normals must have the same shape as the points")
        if k.shape != (X.shape[0],):
            raise ModelError("every point needs a probe")
        if not np.all(np.isfinite(X)) or not np.all(np.isfinite(N)):
            raise ModelError("points and normals must be finite numbers")
        if len(self.probes) == 0 or k.min(initial=0) < 0 or k.max(initial=0) >= len(self.probes):
            raise ModelError("probe index out of range")
        object.__setattr__(self, "X_mm", X)
        object.__setattr__(self, "N", N)
        object.__setattr__(self, "probe_index", k)
        if not self.labels:
            object.__setattr__(self, "labels", tuple(f"X{i + 1}" for i in range(X.shape[0])))
        if self.temperature_C is not None:
            t = np.asarray(self.temperature_C, dtype=float)
            if t.shape != (X.shape[0],) or not np.all(np.isfinite(t)):
                raise ModelError("temperatures must be one finite number (°C) per point")
            object.__setattr__(self, "temperature_C", t)

    @property
    def W_on(self) -> bool:
        """Whether the factor W acts (a workpiece, switched on)."""
        return self.workpiece is not None and self.workpiece.enabled

    @property
    def m(self) -> int:
        return self.X_mm.shape[0]

    @property
    def offsets_mm(self) -> np.ndarray:
        """p_k(i) for every point (m x 3)."""
        P = np.array([p.offset_mm for p in self.probes], dtype=float).reshape(-1, 3)
        return P[self.probe_index]

    @property
    def ram_mm(self) -> np.ndarray:
        """Machine positions x_i - p_k(i) (m x 3) on which the S, ET and ER models act."""
        return self.X_mm - self.offsets_mm
