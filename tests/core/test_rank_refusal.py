"""A Gaussian-process factor whose low-rank factor would need more pivots than allowed (a whole
table scanned with a short correlation length) is refused before any pivoting, with a message
that says what fits (xlfuncs.lowrank.check_rank); what the message proposes fits."""

import re

import numpy as np
import pytest

from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import features as ft
from cmmwb.xlfuncs import lowrank as lr
from cmmwb.xlfuncs import pointcloud as pc

PARAMS = pc.Parameters(0.2, 0.7, 0.7, 0.7, 0.2, 0.2, 30.0, 4.0, 400.0, 0.1, 0.1, 0.5)


def plane(m, a, b, seed=0):
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(0, a, m), rng.uniform(0, b, m), rng.normal(scale=1e-3, size=m)])
    N = np.tile([0.0, 0.0, 1.0], (m, 1))
    return pc.PointCloud(X, N, np.zeros(m, dtype=int), (pc.Probe("P1", (0.0, 0.0, -50.0)),))


def test_a_table_scanned_with_a_short_correlation_length_is_refused_with_what_fits():
    cloud = plane(20_000, 800.0, 600.0)
    f = ft.fit("plane", cloud.X_mm, normals=cloud.N)
    with pytest.raises(lr.RankError) as e:
        bl.propagate_cloud(f, cloud, PARAMS, method="lowrank")
    msg = str(e.value)
    assert msg.startswith("ET: the correlation length 30 mm is short against the extent of the 20,000 points")
    assert "more than the 2,000 it allows" in msg and "exact O(m^2) path" in msg
    a, b = map(float, re.search(r"a section of about (\d+) x (\d+) mm", msg).groups())
    lam = float(re.search(r"a correlation length of at least about (\d+) mm", msg).group(1))
    assert 200 < a < 800 and 150 < b < 600 and abs(a / b - 800 / 600) < 0.02 and 30 < lam < 120
    # what it proposes passes the same check
    lr.check_rank(plane(20_000, a, b, seed=1).X_mm, 1 / 30.0**2, "ET")
    lr.check_rank(cloud.X_mm, 1 / lam**2, "ET")


def test_the_structured_diagnosis_refuses_the_same_way(monkeypatch):
    cloud = plane(8_000, 800.0, 600.0)
    from cmmwb.xlfuncs.locator.structured import StructuredCovariance

    with pytest.raises(lr.RankError, match=r"^ET: .* What fits: a section of about"):
        StructuredCovariance(cloud, PARAMS, 3)


def test_a_kernel_that_runs_into_the_limit_is_refused_saying_so(monkeypatch):
    """200 x 150 mm at lambda 30 mm, 3,000 points: the cell estimate (about 540) is a little
    below the 547 pivots the kernel needs; with the limit set to the estimate, the estimate
    passes and the pivoting runs into the limit."""
    Z = plane(3_000, 200.0, 150.0).X_mm
    est = lr.rank_estimate(Z, 1 / 30.0**2)[0]
    assert 500 < est < 547
    monkeypatch.setattr(lr, "MAX_RANK", est)
    with pytest.raises(lr.RankError, match=rf"^ET: .*ran into the limit of {est} pivots.*What fits"):
        lr.controlled_factor(Z, 1 / 30.0**2, name="ET")
