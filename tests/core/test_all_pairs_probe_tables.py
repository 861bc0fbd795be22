"""The all-pairs kernel takes the terms that are constant per probe pair (PQ, p_i.p_j, the probing
factors of Forbes 2025 sections 6.5-6.6) from per-probe tables: every component still equals the
pair-by-pair evaluation of eq. (29), also with a probe that measured no point."""

import numpy as np

from cmmwb.xlfuncs import pointcloud as pc

from tests.helpers.clouds import PARAMS, PROBES, random_cloud

REL = 1e-10


def components_agree(cloud):
    streamed = pc.distance_components(cloud, PARAMS, block=500)
    listed = pc.distance_components(cloud, PARAMS, pc.all_pairs(cloud.m))
    for key, v in listed.items():
        scale = max(float(np.max(np.abs(v))), 1e-300)
        assert np.max(np.abs(streamed[key] - v)) <= REL * scale, key
    return streamed


def test_every_component_equals_the_pair_by_pair_form_with_three_probes():
    streamed = components_agree(random_cloud(120))
    same = np.sum(streamed["u_PQ_um"] == 0.0)            # pairs of one probe: no PQ term (eq. 9)
    assert 0 < same < streamed["u_PQ_um"].size


def test_a_probe_without_points_leaves_the_others_tables_right():
    cloud = random_cloud(90)
    k = np.where(cloud.probe_index == 1, 2, cloud.probe_index)   # probe P2 measured nothing
    components_agree(pc.PointCloud(cloud.X_mm, cloud.N, k, PROBES, cloud.labels))
