"""One record per hyper-parameter of the model, and one per influence factor: every fact about a
hyper-parameter is typed here once, and every table the rest of cmmwb needs is derived from these
records (the way scikit-learn's ``Hyperparameter`` describes a kernel's parameters, or the
locator's ``EFFECTS`` its candidate effects).

A :class:`Hyperparameter` holds the task-file name and unit, the factor it belongs to, its role in
the covariance (a standard deviation entering as sigma² B with B fixed, the standard deviation of a
Gaussian-process kernel, or the kernel's length scale with its partner standard deviation), the
paper's symbol and the cell note, the plausible range (warned about outside), the measurement that
identifies it in a calibration, whether a probe may override it, and the task-file table it is
read from.  A :class:`Factor` holds an influence factor's label, its title and equation.

Derived here: ``FACTORS``, ``NAMES``, ``UNITS``, ``PARTNER``, ``LINEAR``, ``GP``, ``SIGMAS``,
``MACHINE_SIGMAS``, ``PROBE_OVERRIDES``, ``S_COLUMNS``; elsewhere (each a comprehension over
``HYPERPARAMETERS``): ``xlfuncs.limits.PLAUSIBLE``, ``xlfuncs.calibrate.ADVICE``, the notes and
units of the workbooks' Inputs sheet.  ``tests/core/test_hyperparameters.py`` checks that
:class:`xlfuncs.model.Parameters` has exactly these fields, in this order.

Forbes 2025 (Tables 1 and 3, eq. 28) gives the six machine factors R, PQ, S, ET, ER, P; the
seventh, W, is the workpiece's thermal expansion (``docs/workpiece.md``): its standard deviations
are u(alpha) and u(T) of the part, read from the task's ``[workpiece]`` table, and it is not part of
the machine's MPE statement.
"""

from __future__ import annotations

from dataclasses import dataclass

#: what a hyper-parameter is in the covariance: ``linear`` a standard deviation entering as
#: sigma² B with B fixed; ``gp`` the standard deviation of a kernel whose length scale is a
#: hyper-parameter too; ``lambda`` that length scale
ROLES = ("linear", "gp", "lambda")


@dataclass(frozen=True)
class Factor:
    """An influence factor of eq. (28) (Forbes 2025 section 2.4), or the workpiece's W."""

    label: str           # "R", "PQ", ...: the key of V_X components, JSON u_<label>_um
    name: str            # what metrologists call it
    title: str           # the formula of its covariance, with the paper's equation
    machine: bool = True  # part of the machine's model (its MPE statement); False: the workpiece's


@dataclass(frozen=True)
class Hyperparameter:
    """Every fact about one hyper-parameter (see the module docstring)."""

    name: str                        # task-file key, with its unit in the name
    unit: str                        # unit of the value ("1": dimensionless)
    factor: str                      # the Factor.label it belongs to
    role: str                        # one of ROLES
    symbol: str                      # the paper's symbol
    note: str                        # cell note and meaning on the Inputs sheet
    plausible: tuple[float, float]   # what real machines and parts have (warned about outside)
    advice: str                      # the measurement that identifies it (cmmwb calibrate)
    partner: str | None = None       # role "lambda": the standard deviation whose kernel it shapes
    per_probe: bool = False          # a [[probes]] entry may override it
    table: str = "parameters"        # the task-file table it is read from
    range_unit: str | None = None    # the unit as the plausibility message words it (default: unit)

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise ValueError(f"{self.name}: role must be one of {ROLES}")
        if (self.role == "lambda") != (self.partner is not None):
            raise ValueError(f"{self.name}: a length scale, and only a length scale, has a partner")


FACTOR_RECORDS: tuple[Factor, ...] = (
    Factor("R", "repeatability", "repeatability, Forbes 2025 eq. (8): sigma_R^2 I"),
    Factor("PQ", "probe qualification",
           "probe qualification, eq. (9): sigma_PQ,k^2 I_3 between points of the same probe"),
    Factor("S", "scale and squareness",
           "scale and squareness, eqs. (11)-(14): G_X|S V_B G_X|S^T with G at x_i - p_k(i)"),
    Factor("ET", "location errors",
           "location errors, eq. (21): sigma_ET^2 exp(-||u_i - u_j||^2/lambda_ET^2), per axis, u = x - p"),
    Factor("ER", "rotation errors",
           "rotation errors, eq. (25): sigma_ER^2 exp(-||u_i - u_j||^2/lambda_ER^2) G_k(i) G_k(j)^T"),
    Factor("P", "probing",
           "probing, eq. (27): n_i n_j^T (sigma_P0^2 + sigma_P^2 exp(-||n_i - n_j||^2/lambda_P^2)), same probe"),
    Factor("W", "workpiece temperature",
           "workpiece thermal expansion (docs/workpiece.md): u^2(eps) (x_i - x0)(x_j - x0)^T, "
           "u^2(eps) = (T - 20)^2 u^2(alpha) + alpha^2 u^2(T) (+ the uncorrected expansion, RSS)",
           machine=False),
)

HYPERPARAMETERS: tuple[Hyperparameter, ...] = (
    Hyperparameter("sigma_R_um", "µm", "R", "linear", "sigma_R", "Repeatability, Forbes 2025 eq. (8)",
                   (0.001, 50.0), "repeated records (each length or point measured several times)"),
    Hyperparameter("sigma_S_ppm", "ppm", "S", "linear", "sigma_S", "Global scale, eq. (13) (1e-6)",
                   (0.001, 100.0),
                   "one machine shows one draw of its scale error: lengths in many directions and positions "
                   "give its value (fit 'scale' as an effect and compensate it) rather than its spread; the "
                   "spread needs several machines or re-verifications"),
    Hyperparameter("sigma_Sa_ppm", "ppm", "S", "linear", "sigma_S,a", "Per-axis scale sigma_S,a, eq. (13) (1e-6)",
                   (0.001, 100.0),
                   "lengths along x, y and z (the per-axis scale errors are one draw each per machine: "
                   "their spread needs several machines or re-verifications)"),
    Hyperparameter("sigma_Q_ppm", "ppm", "S", "linear", "sigma_Q", "Squareness sigma_Q, eq. (13) (1e-6 = µrad)",
                   (0.001, 100.0),
                   "lengths along the face and space diagonals (the squareness errors are one draw each per "
                   "machine: their spread needs several machines or re-verifications)"),
    Hyperparameter("sigma_PQ_um", "µm", "PQ", "linear", "sigma_PQ",
                   "Probe qualification, eq. (9); default for every probe", (0.001, 50.0),
                   "records with two or more probes (probe changes) measuring the same artefact",
                   per_probe=True),
    Hyperparameter("sigma_ET_um", "µm", "ET", "gp", "sigma_ET", "Location errors GP, eq. (21)", (0.001, 50.0),
                   "positions spread over several correlation lengths along each axis (step gauge or "
                   "ball plate in several places)"),
    Hyperparameter("lambda_ET_mm", "mm", "ET", "lambda", "lambda_ET",
                   "Length scale of the location-error GP, eq. (21)", (1.0, 1e5),
                   "positions spread over several correlation lengths lambda_ET along each axis, and "
                   "closely spaced ones (a step gauge) to see the correlation decay", partner="sigma_ET_um"),
    Hyperparameter("sigma_ER_urad", "µrad", "ER", "gp", "sigma_ER", "Rotation errors GP, eq. (25)",
                   (0.01, 1000.0),
                   "two or more probe offsets of different direction and length (ISO 10360-2 with "
                   "offset styli): with one offset a rotation is indistinguishable from a translation"),
    Hyperparameter("lambda_ER_mm", "mm", "ER", "lambda", "lambda_ER",
                   "Length scale of the rotation-error GP, eq. (25)", (1.0, 1e5),
                   "two or more probe offsets, and positions spread over several lambda_ER",
                   partner="sigma_ER_urad"),
    Hyperparameter("sigma_P0_um", "µm", "P", "linear", "sigma_P0",
                   "Probe radius uncertainty, eq. (27); default for every probe", (0.001, 50.0),
                   "points probed along many directions with one probe (a sphere, holes; bidirectional "
                   "lengths)", per_probe=True),
    Hyperparameter("sigma_P_um", "µm", "P", "gp", "sigma_P",
                   "Direction-correlated probing GP, eq. (27); default for every probe", (0.001, 50.0),
                   "many probing directions with one probe (a reference sphere probed at 25 or more points)",
                   per_probe=True),
    Hyperparameter("lambda_P", "1", "P", "lambda", "lambda_P",
                   "Length scale (chordal, unit sphere) of the probing GP, eq. (27)", (0.01, 10.0),
                   "many probing directions with one probe, some close together (a densely probed sphere)",
                   partner="sigma_P_um", per_probe=True, range_unit="(unit normals)"),
    Hyperparameter("u_alpha_ppm_per_K", "ppm/K", "W", "linear", "u(alpha)",
                   "u of the part's alpha (1e-6/K): the term (T - 20) u(alpha) of u(eps)", (0.01, 20.0),
                   "records of one artefact at several temperatures show one draw of its alpha error: the "
                   "locator's 'thermal_expansion' effect estimates that draw (fit it and feed it back); the "
                   "spread needs several artefacts of the material", table="workpiece"),
    Hyperparameter("u_T_K", "K", "W", "linear", "u(T)",
                   "u of the part's temperature T (K): the term alpha u(T) of u(eps)", (0.001, 10.0),
                   "a second, calibrated thermometer on the artefact (a thermometer's error is common to "
                   "all records and acts as a scale error)", table="workpiece"),
)

#: the factors of eq. (28) and W, in the order of the V_X components and the JSON
FACTORS: tuple[str, ...] = tuple(f.label for f in FACTOR_RECORDS)
#: the machine's factors (its MPE statement's model: Forbes 2025 eq. (28))
MACHINE_FACTORS: tuple[str, ...] = tuple(f.label for f in FACTOR_RECORDS if f.machine)
FACTOR = {f.label: f for f in FACTOR_RECORDS}
HYPER = {h.name: h for h in HYPERPARAMETERS}
NAMES: tuple[str, ...] = tuple(HYPER)
UNITS = {h.name: h.unit for h in HYPERPARAMETERS}
#: the standard deviation whose kernel a length scale shapes
PARTNER = {h.name: h.partner for h in HYPERPARAMETERS if h.partner is not None}
#: standard deviations entering the covariance linearly in sigma² (their B is fixed)
LINEAR: tuple[str, ...] = tuple(h.name for h in HYPERPARAMETERS if h.role == "linear")
#: the Gaussian-process factors: (standard deviation, length scale, factor)
GP: tuple[tuple[str, str, str], ...] = tuple((s, lm, HYPER[s].factor) for lm, s in PARTNER.items())
#: every standard deviation (not a length scale)
SIGMAS: tuple[str, ...] = tuple(h.name for h in HYPERPARAMETERS if h.role != "lambda")
#: the machine's standard deviations, rescaled by C_max (Forbes 2025 section 6.8)
MACHINE_SIGMAS: tuple[str, ...] = tuple(n for n in SIGMAS if FACTOR[HYPER[n].factor].machine)
#: what a [[probes]] entry may override, in the order of the probes tables
PROBE_OVERRIDES: tuple[str, ...] = tuple(h.name for h in HYPERPARAMETERS if h.per_probe)
#: the standard deviation of each of the seven columns b_aa, b_xx, b_yy, b_zz, b_xy, b_xz, b_yz of
#: V_B (Forbes 2025 eqs. 12-13)
S_COLUMNS: tuple[str, ...] = ("sigma_S_ppm",) + ("sigma_Sa_ppm",) * 3 + ("sigma_Q_ppm",) * 3


def of_factor(factor: str) -> tuple[str, ...]:
    """The hyper-parameters of one factor, in record order."""
    return tuple(h.name for h in HYPERPARAMETERS if h.factor == factor)


def in_table(table: str) -> tuple[str, ...]:
    """The hyper-parameters a task file reads from ``[table]``."""
    return tuple(h.name for h in HYPERPARAMETERS if h.table == table)


def in_use(params) -> tuple[str, ...]:
    """The hyper-parameters a report of ``params`` lists: those of ``[parameters]`` always, the
    others (the part's u(alpha), u(T)) when they are not zero."""
    return tuple(h.name for h in HYPERPARAMETERS if h.table == "parameters" or getattr(params, h.name) != 0)
