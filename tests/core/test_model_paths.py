"""Every evaluation path of the six-factor model and the workpiece's W against its one definition
(xlfuncs.model).

The six factor covariances of Forbes 2025 eq. (28) are defined once, in block form
(:func:`xlfuncs.model.factor_block`, points I x points J) and diagonal form
(:func:`xlfuncs.model.factor_diagonal`, the 3 x 3 blocks V_ii); as a kernel library checks each
kernel's ``diag`` against ``K``, each path here is checked against those two: dense V_X, blocked
blocks and pair blocks, distances (eq. 29), V_A (exact, and low rank within its stated bound),
the structured operators of the locator (C v against the dense C v, within eps_C), the Monte
Carlo sampler (its covariance, and a sample covariance within its statistical tolerance), the
simulator's draws (sample covariance) and the locator's length-record covariance.  The last
tests read the source and fail on a second definition of the model's pieces, or on Table 3's
MPE1/MPE2 typed again in Python or as a TOML ``[parameters]`` table (planted retypings show that
the search finds them).
"""

from __future__ import annotations

import re
from dataclasses import replace
from fnmatch import fnmatch
from pathlib import Path

import numpy as np
import pytest

from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import lowrank as lr
from cmmwb.xlfuncs import montecarlo as mc
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.locator import model as lm
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.structured import StructuredCovariance
from cmmwb.xlfuncs.locator.structured_lengths import LengthCovariance, structure_check
from cmmwb.xlfuncs.model import (
    FACTORS,
    MPE1,
    TABLE3,
    Workpiece,
    factor_block,
    factor_diagonal,
    gauss_kernel,
    sq_dists,
)
from cmmwb.xlfuncs.model.hyperparameters import in_table

ROOT = Path(__file__).resolve().parents[2]

PARAMS = pc.Parameters(sigma_R_um=0.2, sigma_S_ppm=0.7, sigma_Sa_ppm=0.5, sigma_Q_ppm=0.9, sigma_PQ_um=0.2,
                       sigma_ET_um=0.3, lambda_ET_mm=150, sigma_ER_urad=4.0, lambda_ER_mm=350,
                       sigma_P0_um=0.1, sigma_P_um=0.15, lambda_P=0.5, u_alpha_ppm_per_K=1.0, u_T_K=0.3)
#: the factor W with every term: a part at 23.5 °C corrected with a nominal alpha off by 1e-6/K (the
#: uncorrected expansion), 0.4 K across it, held away from the origin
PART = Workpiece(23.0, 23.5, alpha_corr_ppm_per_K=22.0, fixture_mm=(10.0, -20.0, 5.0), dT_K=0.4)
PROBES = (pc.Probe("P1", (0.0, 0.0, -50.0)),
          pc.Probe("P2", (10.0, 40.0, -30.0), sigma_PQ_um=0.3, sigma_P0_um=0.05, lambda_P=0.7),
          pc.Probe("P3", (-20.0, 5.0, -10.0), sigma_P_um=0.0))


def make_cloud(m: int, seed: int = 1, probes=PROBES, part=PART, temperatures: bool = True) -> pc.PointCloud:
    """m random points; with the part PART and (``temperatures``) a temperature per point (records at
    several temperatures: the general rank-3 W), or the part's one temperature."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-300.0, 300.0, (m, 3))
    N = rng.normal(size=(m, 3))
    N /= np.linalg.norm(N, axis=1)[:, None]
    t = part.T_degC + rng.uniform(-2.0, 2.0, m) if part is not None and temperatures else None
    return pc.PointCloud(X, N, rng.integers(0, len(probes), m), probes, workpiece=part, temperature_C=t)


CLOUD = make_cloud(40)
#: the paths of large recordings refuse the factor W (xlfuncs.locator.structured.NO_WORKPIECE)
MACHINE_CLOUD = replace(CLOUD, workpiece=None, temperature_C=None)


def rel_err(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(np.max(np.abs(b)), 1e-300))


@pytest.fixture(scope="module")
def dense():
    return factor_block(CLOUD, PARAMS)


# ---- the two forms of the one definition ---------------------------------------------------

def test_table3_is_typed_once_and_reads_as_the_paper():
    assert MPE1 is TABLE3["MPE1"].params
    assert (TABLE3["MPE1"].A_um, TABLE3["MPE1"].B_mm, TABLE3["MPE2"].A_um, TABLE3["MPE2"].B_mm) == (1.0, 500.0, 3.0, 200.0)
    assert TABLE3["MPE2"].params.sigma_ER_urad == 12.0 and TABLE3["MPE2"].params.lambda_ET_mm == 100.0


def test_the_dense_V_X_is_the_block_form_over_every_point(dense):
    for d_log in (False, True):
        V = pc.V_X_components(CLOUD, PARAMS, d_log_lambda=d_log)
        ref = factor_block(CLOUD, PARAMS, d_log_lambda=d_log)
        assert list(V) == list(FACTORS)
        for f in FACTORS:
            assert np.array_equal(V[f], ref[f]), f


@pytest.mark.parametrize("d_log", [False, True])
def test_the_diagonal_form_is_the_diagonal_of_the_block_form(d_log):
    full = factor_block(CLOUD, PARAMS, d_log_lambda=d_log)
    diag = factor_diagonal(CLOUD, PARAMS, d_log_lambda=d_log)
    m = CLOUD.m
    for f in FACTORS:
        blocks = full[f].reshape(m, 3, m, 3)[np.arange(m), :, np.arange(m), :]
        assert diag[f].shape == (m, 3, 3)
        assert np.max(np.abs(diag[f] - blocks)) <= 1e-13 * max(np.max(np.abs(full[f])), 1e-300), f


def test_every_factor_is_symmetric_positive_semidefinite(dense):
    for f in FACTORS:
        assert np.array_equal(dense[f], dense[f].T) or rel_err(dense[f], dense[f].T) <= 1e-15, f
        w = np.linalg.eigvalsh(dense[f])
        assert w[0] >= -1e-12 * max(w[-1], 1e-300), f


def test_blocked_blocks_are_sub_blocks_of_the_dense_V_X(dense):
    I, J = np.array([3, 17, 5, 39]), np.arange(0, 40, 3)
    blk = bl.V_X_block(CLOUD, PARAMS, I, J)
    rows = (3 * I[:, None] + np.arange(3)).ravel()
    cols = (3 * J[:, None] + np.arange(3)).ravel()
    for f in FACTORS:
        assert rel_err(blk[f], dense[f][np.ix_(rows, cols)]) <= 1e-13, f
    assert rel_err(bl.V_X_dense(CLOUD, PARAMS, rows_per_block=7), pc.V_X(CLOUD, PARAMS)) <= 1e-13


def test_pair_blocks_are_V_ii_plus_V_jj_minus_the_cross_blocks(dense):
    pairs = np.array([[0, 1], [7, 22], [39, 3], [12, 30]])
    pb = bl.pair_blocks(CLOUD, PARAMS, pairs)
    m = CLOUD.m
    for f in FACTORS:
        V = dense[f].reshape(m, 3, m, 3)
        for q, (i, j) in enumerate(pairs):
            ref = V[i, :, i, :] + V[j, :, j, :] - V[i, :, j, :] - V[j, :, i, :]
            assert np.max(np.abs(pb[f][q] - ref)) <= 1e-12 * max(np.max(np.abs(dense[f])), 1e-300), f


@pytest.mark.parametrize("temperatures", [True, False])
def test_distance_components_are_the_quadratic_form_of_eq_29(temperatures):
    """Both the all-pairs kernel and the given-pairs path; u = sqrt(g^T V g) cancels, so the
    dense reference holds about 9 digits.  W with a temperature per point (its columns) and with the
    part's one temperature (d u(eps))."""
    cloud = make_cloud(40, temperatures=temperatures)
    dense = factor_block(cloud, PARAMS)
    pairs = pc.all_pairs(cloud.m)[::37]
    every = pc.distance_components(cloud, PARAMS)
    given = pc.distance_components(cloud, PARAMS, pairs)
    for q, (i, j) in enumerate(pairs):
        n = (cloud.X_mm[j] - cloud.X_mm[i]) / np.linalg.norm(cloud.X_mm[j] - cloud.X_mm[i])
        g = np.zeros(3 * cloud.m)
        g[3 * i:3 * i + 3], g[3 * j:3 * j + 3] = -n, n
        for f in FACTORS:
            ref = np.sqrt(max(g @ dense[f] @ g, 0.0))
            assert every[f"u_{f}_um"][37 * q] == pytest.approx(ref, rel=1e-9, abs=1e-12), f
            assert given[f"u_{f}_um"][q] == pytest.approx(ref, rel=1e-9, abs=1e-12), f
        assert given["u_W_um"][q] > 0.1


# ---- the paths that never form V_X -----------------------------------------------------------

def test_V_A_exact_and_low_rank_within_the_stated_bound():
    cloud = make_cloud(300, seed=4)
    G = np.random.default_rng(5).normal(size=(4, 3 * cloud.m))
    V = factor_block(cloud, PARAMS)
    exact = bl.V_A_components(G, cloud, PARAMS, block=5000)
    approx = lr.Approximation()
    low = bl.V_A_components(G, cloud, PARAMS, method="lowrank", approximation=approx)
    for f in FACTORS:
        ref = G @ V[f] @ G.T
        assert rel_err(exact[f], ref) <= 1e-12, f
        tol = approx.bound_abs[f] if f in approx.bound_abs else 0.0
        assert np.all(np.abs(low[f] - ref) <= tol + 1e-12 * np.max(np.abs(ref))), f


def test_the_low_rank_unit_kernel_is_the_model_kernel():
    A, B = CLOUD.ram_mm[:10], CLOUD.ram_mm[5:]
    # exp(-D^2 * (1/lambda^2)) there, exp(-D^2 / lambda^2) here: the exponents differ by rounding
    assert np.allclose(lr.unit_kernel(A, B, 1 / 150.0**2), gauss_kernel(sq_dists(A, B), 150.0**2), rtol=1e-14, atol=0)


@pytest.mark.parametrize("dims", [3, 2])
def test_the_structured_point_covariance_applies_the_dense_C_within_eps_C(dims):
    S = StructuredCovariance(MACHINE_CLOUD, PARAMS, dims)
    keep = np.array([3 * i + a for i in range(CLOUD.m) for a in range(dims)])
    C = pc.V_X(MACHINE_CLOUD, PARAMS)[np.ix_(keep, keep)]
    U = np.vstack([blk for _i0, _i1, blk in S.blocks()])
    v = np.random.default_rng(2).normal(size=(C.shape[0], 3))
    Cv = S.d * v + U @ (U.T @ v)
    slack = S.eps_C + 1e-12 * np.max(np.abs(C))
    assert np.all(np.linalg.norm(Cv - C @ v, axis=0) <= slack * np.linalg.norm(v, axis=0))
    assert np.max(np.abs(S.diagonal() - np.diag(C))) <= slack


def test_the_structured_length_covariance_applies_the_dense_C_within_eps_C():
    m = 30
    I, J = np.zeros(m - 1, dtype=int), np.arange(1, m)      # one shared start, own ends
    cloud = make_cloud(m, seed=6, part=None)
    assert structure_check(I, J, m) is None
    L = LengthCovariance(cloud, PARAMS, I, J)
    C = lm.length_covariance(cloud, PARAMS, I, J)
    v = np.random.default_rng(3).normal(size=(len(I), 2))
    slack = L.eps_C + 1e-12 * np.max(np.abs(C))
    assert np.all(np.linalg.norm(L.matvec(v) - C @ v, axis=0) <= slack * np.linalg.norm(v, axis=0))


def test_the_structured_operators_refuse_the_factor_W_with_the_way_out():
    with pytest.raises(pc.ModelError, match=r"\[workpiece\].*dense"):
        StructuredCovariance(CLOUD, PARAMS, 3)
    with pytest.raises(pc.ModelError, match=r"\[workpiece\].*dense"):
        LengthCovariance(make_cloud(30, seed=6), PARAMS, np.zeros(29, dtype=int), np.arange(1, 30))


def test_the_locator_length_covariance_is_G_V_X_G_T_also_its_derivative():
    rng = np.random.default_rng(7)
    I = rng.integers(0, CLOUD.m, 25)
    J = (I + rng.integers(1, CLOUD.m, 25)) % CLOUD.m
    d = CLOUD.X_mm[J] - CLOUD.X_mm[I]
    na = d / np.linalg.norm(d, axis=1)[:, None]
    G = np.zeros((len(I), 3 * CLOUD.m))
    for a in range(len(I)):
        G[a, 3 * I[a]:3 * I[a] + 3] -= na[a]
        G[a, 3 * J[a]:3 * J[a] + 3] += na[a]
    for d_log in (False, True):
        V = factor_block(CLOUD, PARAMS, d_log_lambda=d_log)
        C = lm.length_covariance(CLOUD, PARAMS, I, J, components=True, d_log_lambda=d_log)
        for f in FACTORS:
            ref = G @ V[f] @ G.T
            assert np.max(np.abs(C[f] - ref)) <= 1e-12 * max(np.max(np.abs(ref)), 1e-300), (f, d_log)


# ---- the draws -------------------------------------------------------------------------------

def within_sampling_tolerance(S: np.ndarray, V: np.ndarray, M: int, z: float = 5.0) -> bool:
    """Sample covariance S of M draws against V: every entry within z standard errors,
    sd(S_ij) = sqrt((V_ij^2 + V_ii V_jj) / M) for normal draws."""
    sd = np.sqrt((V**2 + np.outer(np.diag(V), np.diag(V))) / M)
    return bool(np.all(np.abs(S - V) <= z * sd + 1e-12))


def test_the_monte_carlo_sampler_draws_the_model():
    cloud = make_cloud(6, seed=8)
    V = factor_block(cloud, PARAMS)
    smp = mc.PointCloudSampler(cloud, PARAMS)
    for f in FACTORS:
        assert np.max(np.abs(smp.covariance(f) - V[f])) <= 1e-12 * max(np.max(np.abs(V[f])), 1e-300), f
    M = 20_000
    draws = smp.draw(M, np.random.default_rng(9))
    x = sum(draws[f] for f in FACTORS).reshape(M, -1)
    assert within_sampling_tolerance(x.T @ x / M, sum(V.values()), M)


def test_the_simulator_draws_the_model():
    """The simulator draws the machine's six factors (the part's expansion is its planted
    thermal_expansion effect)."""
    cloud = make_cloud(5, seed=10, part=None)
    V = pc.V_X(cloud, PARAMS)
    rng = np.random.default_rng(11)
    M = 4000
    x = np.array([sm.model_errors(cloud.X_mm, cloud.N, cloud.probe_index, cloud.probes, PARAMS, rng).ravel()
                  for _ in range(M)])
    assert within_sampling_tolerance(x.T @ x / M, V, M)


# ---- one definition: read the source ---------------------------------------------------------
#
# Patterns (Python source of xlfuncs/ and generator/, xlfuncs/model/ excepted):
#   * a squared-distance helper: ``def`` of a name containing ``sq_dist``/``sqdist``/``sq_dists``;
#     generator/pointcloud/vx_sheets.py's ``_sqdist`` writes the spreadsheet formula text of the
#     same quantity (the engines' agreement with the core is tested on the workbooks) and is
#     the one exception;
#   * the cancelling form |a|^2 + |b|^2 - 2 a.b: ``2 * <name> @ <name>.T`` or ``2.0 * ...``;
#   * a skew / G_S helper: ``def`` of ``skew*``, ``G_S*``, ``G_X_S``;
#   * the six factor covariances: ``def factor_block``/``factor_diagonal``, the 3m x 3m expansion
#     of a kernel (``kron(`` with a kernel, ``rho``, ``kern`` or ``exp``) or the interleaved
#     normal products ``"ia,jb->iajb"`` of the probing factor;
#   * Table 3's MPE1 typed out again as ``Parameters(...)`` keywords: ``sigma_Sa_ppm=0.7,
#     sigma_Q_ppm=0.7, sigma_PQ_um=0.2(0),`` followed by ``sigma_ET_um=0.2, lambda_ET_mm=200`` (also in
#     tests/ and bench/); the tests of Table 3 typed as text (TOML, keywords, dict) follow below.

PATTERNS = {
    "squared distance": re.compile(r"^\s*def \w*(sq_?dist)\w*\(", re.M),
    "cancelling distance": re.compile(r"2(\.0)? \* \w+ @ \w+\.T"),
    "skew / G_S": re.compile(r"^\s*def (skew\w*|G_S\w*|G_X_S)\(", re.M),
    "factor covariances": re.compile(r"^\s*def (factor_block|factor_diagonal)\(|kron\([^)\n]*(kern|rho|exp|gauss)"
                                     r"|\"ia,jb->iajb\"", re.M),
}
TABLE3_TYPED = re.compile(r"sigma_Sa_ppm=0\.7, sigma_Q_ppm=0\.7, sigma_PQ_um=0\.20?,\s*sigma_ET_um=0\.2, lambda_ET_mm=200")
EXCEPTIONS = {("squared distance", "generator/pointcloud/vx_sheets.py")}


def sources(*tops: str):
    for top in tops:
        for p in sorted((ROOT / top).rglob("*.py")):
            rel = p.relative_to(ROOT).as_posix()
            if not rel.startswith("xlfuncs/model/"):
                yield rel, p.read_text(encoding="utf-8")


def test_the_model_pieces_are_defined_once():
    found = [(name, rel) for rel, text in sources("xlfuncs", "generator")
             for name, pat in PATTERNS.items() if pat.search(text) and (name, rel) not in EXCEPTIONS]
    assert found == []
    model = "\n".join(p.read_text(encoding="utf-8") for p in (ROOT / "xlfuncs" / "model").glob("*.py"))
    for name in ("squared distance", "skew / G_S", "factor covariances"):
        assert PATTERNS[name].search(model), name      # the patterns do find the one definition


def test_table3_is_not_typed_out_again():
    found = [rel for rel, text in sources("xlfuncs", "tests", "bench", "generator")
             if TABLE3_TYPED.search(text) and rel != "tests/core/test_model_paths.py"]
    assert found == []


# ---- Table 3 typed as text -------------------------------------------------------------------
#
# A run of parameter assignments (Table 3's names, ``key = value`` lines of TOML, ``key=value``
# keywords or ``"key": value`` dict items, separated only by commas, blanks, line ends and
# comments) is a retyping of MPE1 or MPE2 when it gives at least six of the twelve values and at
# most one of them differs from the scenario's (``dataclasses.replace(MPE1, ...)`` says the
# same). Sets made up for a test (tests.helpers.tasks.ALL_FACTORS, PARAMS above: about six values
# of twelve differ) are not retypings.

TABLE3_KEYS = in_table("parameters")      # the machine's (Table 3 has no workpiece)
ASSIGNMENT = re.compile(r"""(^[ \t]*)?["']?\b(%s)["']?[ \t]*[=:][ \t]*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"""
                        % "|".join(TABLE3_KEYS), re.M)
#: where Table 3 may be typed as TOML lines (test_table3_is_not_typed_out_as_text_again says why)
TOML_TABLE3_ALLOWED = ("generator/examples/*.toml", "generator/pointcloud/job.py", "generator/feature/job.py")


def table3_runs(text: str) -> list[tuple[dict, bool]]:
    """Every run of parameter assignments in ``text``: ({name: value}, typed as TOML lines)."""
    runs, run, toml, end = [], {}, True, None
    for m in ASSIGNMENT.finditer(text):
        if end is not None and re.sub(r"#[^\n]*", "", text[end:m.start()]).strip(" \t\r\n,") != "":
            runs.append((run, toml))
            run, toml = {}, True
        run[m.group(2)] = float(m.group(3))
        line_end = re.match(r"[ \t]*(#|\r?\n|$)", text[m.end():])     # no comma, no bracket after it
        toml = toml and m.group(1) is not None and ":" not in m.group(0) and line_end is not None
        end = m.end()
    return runs + [(run, toml)]


def table3_retypings(text: str) -> list[tuple[str, bool]]:
    """(scenario, typed as TOML lines) of every run of ``text`` that retypes MPE1 or MPE2."""
    return [(name, toml) for run, toml in table3_runs(text) for name, sc in TABLE3.items()
            if len(run) >= 6 and sum(v != getattr(sc.params, k) for k, v in run.items()) <= 1]


def text_sources():
    """The Python sources of sources() and every .toml file of tests/, bench/ and generator/."""
    yield from sources("xlfuncs", "tests", "bench", "generator")
    for top in ("tests", "bench", "generator"):
        for p in sorted((ROOT / top).rglob("*.toml")):
            yield p.relative_to(ROOT).as_posix(), p.read_text(encoding="utf-8")


def test_table3_is_not_typed_out_as_text_again():
    """The MPE1/MPE2 parameters of a task file written by a test or a benchmark come from
    ``tests.helpers.tasks.parameters_toml(MPE1)`` (or ``cmmwb.xlfuncs.model.TABLE3``), not typed.

    Searched: every .py file of xlfuncs/, generator/, tests/, bench/ and every .toml file of
    tests/, bench/, generator/.  Allowed (TOML_TABLE3_ALLOWED), as ``key = value`` lines only:

    * ``generator/examples/*.toml``: the worked examples of the papers that users open, read and
      copy; they are package data (a task file cannot import MPE1) and must read as Table 3 on
      their own;
    * ``generator/pointcloud/job.py`` and ``generator/feature/job.py``: the commented task files
      ``cmmwb new pointcloud|feature`` writes, each key with a comment for the user (the templates
      of workbook_templates/ are built from them and stay as they are).

    The next test checks that these copies still give Table 3's twelve values exactly.  A Python
    ``Parameters(...)`` or dict retyping is caught in every file, these included; this file is
    left out for its planted examples."""
    found = [(rel, name) for rel, text in text_sources() if rel != "tests/core/test_model_paths.py"
             for name, toml in table3_retypings(text)
             if not (toml and any(fnmatch(rel, pat) for pat in TOML_TABLE3_ALLOWED))]
    assert found == []


def test_the_allowed_toml_copies_of_table3_are_found_and_equal_to_it():
    """The exception is used (each pattern matches files that carry Table 3), and every copy gives
    all twelve values of its column exactly, so that a user copying one copies Table 3."""
    for pat in TOML_TABLE3_ALLOWED:
        copies = [(p.name, run) for p in sorted(ROOT.glob(pat)) for run, _toml in table3_runs(p.read_text("utf-8"))
                  if table3_retypings("\n".join(f"{k} = {v}" for k, v in run.items()))]
        assert copies, pat
        for name, run in copies:
            assert any(run == {k: getattr(sc.params, k) for k in TABLE3_KEYS} for sc in TABLE3.values()), (name, run)


PLANTED_TOML = """[task]
kind = "pointcloud"

[parameters]
sigma_R_um = 0.60        # a comment does not break the run
sigma_S_ppm = 2.1
sigma_Sa_ppm = 2.1
sigma_Q_ppm = 2.1
sigma_PQ_um = 0.6
sigma_ET_um = 0.6
lambda_ET_mm = 100
sigma_ER_urad = 12
lambda_ER_mm = 200
sigma_P0_um = 0.3
sigma_P_um = 0.3
lambda_P = 0.5

[[probes]]
id = "P1"
"""


def test_a_planted_toml_retyping_of_mpe2_is_found():
    assert table3_retypings(PLANTED_TOML) == [("MPE2", True)]
    # one value changed is still a retyping of MPE2; two are a parameter set of its own
    assert table3_retypings(PLANTED_TOML.replace("sigma_P_um = 0.3", "sigma_P_um = 0.2")) == [("MPE2", True)]
    assert table3_retypings(PLANTED_TOML.replace("sigma_P_um = 0.3", "sigma_P_um = 0.2")
                            .replace("lambda_P = 0.5", "lambda_P = 0.7")) == []


def test_a_planted_keyword_or_dict_retyping_of_mpe1_is_found_and_not_taken_for_toml():
    keywords = ('PARAMS = pc.Parameters(sigma_R_um=0.2, sigma_S_ppm=0.7, sigma_Sa_ppm=0.7,\n'
                '                       sigma_Q_ppm=0.7, sigma_PQ_um=0.2, sigma_ET_um=0.2, lambda_ET_mm=200)\n')
    one_a_line = "Parameters(\n    sigma_R_um=0.2,\n    sigma_S_ppm=0.7,\n    sigma_Sa_ppm=0.7,\n" \
                 "    sigma_Q_ppm=0.7,\n    sigma_PQ_um=0.2,\n    sigma_ET_um=0.2,\n)\n"
    assert table3_retypings(one_a_line) == [("MPE1", False)]
    items = ('{"sigma_ER_urad": 4.0, "lambda_ER_mm": 400, "sigma_P0_um": 0.1, "sigma_P_um": 0.1, "lambda_P": 0.5,\n'
             ' "sigma_R_um": 0.2}')
    assert table3_retypings(keywords) == [("MPE1", False)]
    assert table3_retypings(items) == [("MPE1", False)]
    assert table3_retypings("sigma_R_um = 0.2\nsigma_S_ppm = 0.7\nx = 1\nsigma_Sa_ppm = 0.7\n") == []   # too few


def test_made_up_parameter_sets_are_not_retypings():
    from tests.helpers.tasks import ALL_FACTORS

    typed = "\n".join(f"{k} = {v}" for k, v in ALL_FACTORS.items())
    assert table3_retypings(typed) == []
    assert table3_retypings(Path(__file__).read_text(encoding="utf-8").partition("PROBES =")[0]) == []   # PARAMS
