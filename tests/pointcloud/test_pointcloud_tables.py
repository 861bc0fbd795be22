"""Forbes 2025 Tables 4 and 5: the step gauge of section 7, reproduced by `cmmwb build` on the
shipped example tasks, every one of the 112 printed numbers to its printed precision."""

import json

import pytest

from cmmwb.generator.cli import build_task

from tests.helpers import EXAMPLES, printed

FACTORS = ("R", "PQ", "S", "ET", "ER", "P")
ROWS = [("L1", "R1"), ("L1", "L2"), ("L1", "L26"), ("L1", "R26")]

# d, u, u_R, u_PQ, u_S, u_ET, u_ER, u_P, as printed
TABLE4 = {
    "MPE1": [(10.00, 0.37, 0.28, 0.00, 0.01, 0.01, 0.00, 0.24),
             (20.00, 0.28, 0.28, 0.00, 0.02, 0.03, 0.01, 0.00),
             (500.00, 0.64, 0.28, 0.00, 0.49, 0.28, 0.10, 0.00),
             (510.00, 0.70, 0.28, 0.00, 0.50, 0.28, 0.10, 0.24)],
    "MPE2": [(10.00, 1.13, 0.85, 0.00, 0.03, 0.08, 0.02, 0.73),
             (20.00, 0.87, 0.85, 0.00, 0.06, 0.17, 0.03, 0.00),
             (500.00, 1.94, 0.85, 0.00, 1.48, 0.85, 0.34, 0.00),
             (510.00, 2.10, 0.85, 0.00, 1.51, 0.85, 0.34, 0.73)],
}
TABLE5 = {
    "MPE1": [(10.00, 0.41, 0.28, 0.14, 0.03, 0.06, 0.16, 0.20),
             (20.00, 0.28, 0.28, 0.00, 0.02, 0.03, 0.01, 0.00),
             (500.00, 0.64, 0.28, 0.00, 0.49, 0.28, 0.10, 0.00),
             (510.00, 0.70, 0.28, 0.14, 0.51, 0.28, 0.12, 0.20)],
    "MPE2": [(10.00, 1.27, 0.85, 0.42, 0.09, 0.34, 0.47, 0.60),
             (20.00, 0.87, 0.85, 0.00, 0.06, 0.17, 0.03, 0.00),
             (500.00, 1.94, 0.85, 0.00, 1.48, 0.85, 0.34, 0.00),
             (510.00, 2.10, 0.85, 0.42, 1.52, 0.85, 0.34, 0.60)],
}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("stepgauge")
    results = {}
    for scenario in ("I", "II"):
        for mpe in ("MPE1", "MPE2"):
            r, files = build_task(EXAMPLES / f"stepgauge_{scenario}_{mpe}.toml", out, plots=False)
            # the JSON on disk is what users get
            results[scenario, mpe] = json.loads((out / f"stepgauge_{scenario}_{mpe}.json").read_text())
    return results


@pytest.mark.parametrize("scenario,table", [("I", TABLE4), ("II", TABLE5)])
@pytest.mark.parametrize("mpe", ["MPE1", "MPE2"])
def test_table_rows_to_printed_precision(built, scenario, table, mpe):
    by_pair = {(d["from"], d["to"]): d for d in built[scenario, mpe]["distances"]}
    for pair, expected in zip(ROWS, table[mpe]):
        d = by_pair[pair]
        got = [d["d_mm"], d["u_um"]] + [d["components_um"][f] for f in FACTORS]
        for name, g, e in zip(["d", "u"] + [f"u_{f}" for f in FACTORS], got, expected):
            assert printed(g, e), f"{scenario}/{mpe} {pair} {name}: {g:.4f} does not print as {e:.2f}"


def test_mpe2_parameters_violate_the_mpe_above_about_885_mm(built):
    """Errata: Table 3's MPE2 column gives C(d) > 1 from about 885 mm (C_max 1.02 at 1000 mm)."""
    chk = built["I", "MPE2"]["mpe_check"]
    assert printed(chk["C_max"], 1.02) and chk["d_at_max_mm"] == 1000.0 and not chk["conforms"]
    import numpy as np

    from cmmwb.xlfuncs import pointcloud as pc

    p = pc.Parameters(**built["I", "MPE2"]["mpe_check"]["conforming_parameters"]).scaled(1 / chk["C_max"])
    d = np.arange(0, 1000.5, 1.0)
    c = pc.C_of_d(d, p, 3.0, 200, 2, 50)
    first = d[np.argmax(c > 1)]
    assert 870 <= first <= 900
    # dividing the sigmas by C_max makes them conform (section 6.8)
    scaled = pc.Parameters(**chk["conforming_parameters"])
    assert pc.mpe_check(scaled, 3.0, 200, 2, 50).C_max <= 1 + 1e-12


def test_mpe1_parameters_conform(built):
    chk = built["I", "MPE1"]["mpe_check"]
    assert chk["conforms"] and chk["C_max"] < 1
