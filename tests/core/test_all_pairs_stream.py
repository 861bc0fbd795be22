"""All-pairs distance uncertainties streamed in float64 blocks (xlfuncs.pointcloud.
iter_distance_components) are the numbers of distance_components, in all_pairs order, whatever
the block size."""

import numpy as np
import pytest

from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.errors import DegenerateGeometryError

from tests.helpers.clouds import PARAMS, random_cloud


@pytest.mark.parametrize("block", [7, 1000, pc.PAIR_BLOCK])
def test_the_streamed_blocks_are_the_arrays_in_order(block):
    cloud = random_cloud(150)
    whole = pc.distance_components(cloud, PARAMS)
    parts = list(pc.iter_distance_components(cloud, PARAMS, block=block, workers=2))
    assert parts[0][0].start == 0 and parts[-1][0].stop == 150 * 149 // 2
    assert all(a[0].stop == b[0].start for a, b in zip(parts, parts[1:]))
    for key, v in whole.items():
        assert np.array_equal(np.concatenate([p[key] for _sl, p in parts]), v), key


def test_pairs_listed_explicitly_agree_with_the_stream():
    cloud = random_cloud(60)
    pairs = pc.all_pairs(cloud.m)
    listed = pc.distance_components(cloud, PARAMS, pairs)
    streamed = np.concatenate([p["u_um"] for _sl, p in pc.iter_distance_components(cloud, PARAMS, block=50)])
    assert np.max(np.abs(streamed - listed["u_um"]) / listed["u_um"]) < 1e-12


def test_two_points_at_one_place_are_named_in_the_stream():
    cloud = random_cloud(40)
    X = cloud.X_mm.copy()
    X[31] = X[17]
    bad = pc.PointCloud(X, cloud.N, cloud.probe_index, cloud.probes, cloud.labels)
    with pytest.raises(DegenerateGeometryError, match=f"points {cloud.labels[17]} and {cloud.labels[31]} "):
        list(pc.iter_distance_components(bad, PARAMS, block=30))
