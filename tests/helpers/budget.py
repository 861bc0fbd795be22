"""Wojtyła/Płowucha 2023: the steering knuckle of section 4 (Fig. 6) and Tables 1-9 as printed, with
the conventions of docs/errata.md (E_L,MPE = 3 + L/250 µm with b = 0.577; x = 0.01 mm for S3 and S4;
u_POS = 2 sqrt(u_l1^2 + u_l2^2)); the printed-precision check; the paper's equations written
literally and numerical derivatives, the independent reference for the closed-form sensitivities."""

from __future__ import annotations

import numpy as np

from cmmwb.xlfuncs.budget import MPE, DatumSystem

#: Fig. 6 / section 4, with x = 0.01 mm for S3 and S4 (the paper's "0.01 mm for numerical
#: reasons": x_CS4 in Table 1, x_DS4 in Table 2, x_DS3 in Tables 7-8)
KNUCKLE = {
    "A": [50, -32, 0], "B": [-50, -32, 0], "C": [0, 61, 0], "D": [0, 0, -15],
    "E": [0, -72, 19], "S1": [45, -26, -15], "S2": [-45, -26, -15],
    "S3": [0.01, 52, -15], "S4": [0.01, 89, 63],
}

DATUMS = DatumSystem(primary=("A", "B", "C"), secondary=("D", "E"))

TABLES_MPE = MPE(A_um=3.0, B_mm=250.0, b=0.577, k=2.0)      # section 6 MicroXcel, errata

SECTION4_MPE = MPE(A_um=2.0, B_mm=250.0, b=1 / 3, k=2.0)    # as stated in section 4

#: (point, datums, TEDs in mm) of the four axis positions, section 4
POSITIONS = {
    "S4": (("primary", "tertiary"), (63.0, 89.0)),
    "S1": (("secondary", "tertiary"), (45.0, 26.0)),
    "S2": (("secondary", "tertiary"), (45.0, 26.0)),
    "S3": (("secondary", "tertiary"), (0.0, 52.0)),
}

# Tables 1-8 as printed: input, x_i (mm), dl/dx_i, u_i (µm), dl/dx_i * u_i (µm).  Strings keep
# the printed precision.  Typesetting garbles fixed: Table 1's last row label reads "B" (z_CB);
# Table 4 prints "0.6671.73" for u(y_AB) and "0.711.812" for u(z_DE) (overprinted values of
# the 2 + L/250, b = 1/3 version: 0.667, 0.71); Table 8 is cut after y_DE (z_DE as in Table 7,
# u_c = 1.85 from the text).
_T_AB = """x_AB -100 0 1.96 0
y_AB 0 0 1.73 0"""

_T_AC = """x_AC -50 0 1.85 0
y_AC 93 0 1.95 0
z_AC 0 0 1.73 0"""

_T_DE = """y_DE -72 0 1.90 0
z_DE 34 0 1.81 0"""

TABLES = {
    # table: (point, datum, the paper's variant (equation), rows, u_c)
    1: ("S4", "primary", "CS4.(CAxCB)", "eq. (18)", """
x_CS4 0.01 0 1.73 0
y_CS4 28 0 1.80 0
z_CS4 63 1 1.88 1.88
x_CA 50 0 1.85 0
y_CA -93 0 1.95 0
z_CA 0 0.150 1.73 0.260
x_CB -50 0 1.85 0
y_CB -93 0 1.95 0
z_CB 0 0.151 1.73 0.261""", "1.91"),
    2: ("S4", "tertiary", "DS4.((CAxCB)x(DEx(CAxCB)))", "eqs. (21), (35)", """
x_DS4 0.01 0 1.73 0
y_DS4 89 1 1.94 1.94
z_DS4 78 0 1.91 0
x_CA 50 0 1.85 0
y_CA -93 0 1.95 0
z_CA 0 -0.419 1.73 -0.726
x_CB -50 0 1.85 0
y_CB -93 0 1.95 0
z_CB 0 -0.419 1.73 -0.726
x_DE 0 0 1.73 0
""" + _T_DE, "2.19"),
    3: ("S1", "secondary", "DS1.(DEx(ABxAC))", "eq. (27)", """
x_DS1 45 1 1.83 1.83
y_DS1 -26 0 1.79 0
z_DS1 0 0 1.73 0
""" + _T_AB + """
z_AB 0 0.123 1.73 0.213
""" + _T_AC + """
x_DE 0 -0.361 1.73 -0.625
""" + _T_DE, "1.95"),
    4: ("S1", "tertiary", "DS1.((ABxAC)x(DEx(ABxAC)))", "eqs. (19), (33)", """
x_DS1 45 0 1.83 0
y_DS1 -26 -1 1.79 -1.79
z_DS1 0 0 1.73 0
""" + _T_AB + """
z_AB 0 -0.212 1.73 -0.368
""" + _T_AC + """
x_DE 0 0.625 1.73 1.08
""" + _T_DE, "2.12"),
    5: ("S2", "secondary", "DS2.(DEx(ABxAC))", "eq. (27)", """
x_DS2 -45 -1 1.83 -1.83
y_DS2 -26 0 1.79 0
z_DS2 0 0 1.73 0
""" + _T_AB + """
z_AB 0 -0.123 1.73 -0.213
""" + _T_AC + """
x_DE 0 0.361 1.73 0.625
""" + _T_DE, "1.95"),
    6: ("S2", "tertiary", "DS2.((ABxAC)x(DEx(ABxAC)))", "eqs. (19), (33)", """
x_DS2 -45 0 1.83 0
y_DS2 -26 -1 1.79 -1.79
z_DS2 0 0 1.73 0
""" + _T_AB + """
z_AB 0 0.212 1.73 0.368
""" + _T_AC + """
x_DE 0 -0.625 1.73 -1.08
""" + _T_DE, "2.12"),
    7: ("S3", "secondary", "DS3.(DEx(ABxAC))", "eq. (27)", """
x_DS3 0.01 1 1.73 1.73
y_DS3 52 0 1.85 0
z_DS3 0 0 1.73 0
""" + _T_AB + """
z_AB 0 -0.246 1.73 -0.425
""" + _T_AC + """
x_DE 0 0.722 1.73 1.25
""" + _T_DE, "2.18"),
    8: ("S3", "tertiary", "DS3.((ABxAC)x(DEx(ABxAC)))", "eqs. (19), (33)", """
x_DS3 0.01 0 1.73 0
y_DS3 52 1 1.85 1.85
z_DS3 0 0 1.73 0
""" + _T_AB + """
z_AB 0 0 1.73 0
""" + _T_AC + """
x_DE 0 0 1.73 0
""" + _T_DE, "1.85"),
}

#: Table 9 (µm): u_1, u_2, u_POS; Table 10's "sensitivity analysis" row repeats u_POS
TABLE9 = {"S4": ("1.91", "2.19", "5.82"), "S1": ("1.95", "2.12", "5.77"),
          "S2": ("1.95", "2.12", "5.77"), "S3": ("2.18", "1.85", "5.72")}


def decimals(text: str) -> int:
    return len(text.split(".")[1]) if "." in text else 0


def assert_printed(value: float, text: str, *, min_decimals: int = 0, what: str = "") -> None:
    """``value`` rounds to the printed ``text``: |value - printed| <= 0.5 * 10**-decimals.

    ``min_decimals`` applies to bare integers only: "0", "1", "-1" in the sensitivity and
    contribution columns stand for the paper's 3 decimal places (section 5), exact coordinate
    differences ("28", "-93") are checked to 0.01 mm like the printed "0.01".
    """
    dec = decimals(text) if "." in text else min_decimals
    assert abs(value - float(text)) <= 0.5 * 10.0**-dec + 1e-12, (
        f"{what}: {value!r} does not print as {text} ({dec} decimals)")


def reference_value(kind: str, x: np.ndarray) -> float:
    """The paper's equations written literally (np.cross, np.dot, norms), on the flat vector of
    input quantities in budget order."""
    v = x.reshape(-1, 3)
    unit = lambda n: n / np.linalg.norm(n)  # noqa: E731
    if kind == "point_point":                                       # eq. (1)
        return float(np.linalg.norm(v[0]))
    if kind == "point_line":                                        # eq. (2)
        return float(np.linalg.norm(np.cross(v[0], unit(v[1]))))
    if kind == "plane":                                             # eq. (3)
        return abs(float(np.dot(v[0], unit(np.cross(v[1], v[2])))))
    if kind == "line_line":                                         # eq. (4): AB, CD, AC
        return abs(float(np.dot(v[2], unit(np.cross(v[0], v[1])))))
    u = np.cross(v[1], v[2])                                        # eq. (7)
    if kind == "secondary":                                         # eqs. (8), (27)
        return abs(float(np.dot(v[0], unit(np.cross(v[3], u)))))
    if kind == "tertiary":                                          # eqs. (9), (19)
        return abs(float(np.dot(v[0], unit(np.cross(u, np.cross(v[3], u))))))
    raise AssertionError(kind)


def numerical_gradient(f, x: np.ndarray, h: float) -> np.ndarray:
    """Five-point central differences (truncation O(h^4))."""
    g = np.empty_like(x)
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        g[i] = (-f(x + 2 * e) + 8 * f(x + e) - 8 * f(x - e) + f(x - 2 * e)) / (12 * h)
    return g
