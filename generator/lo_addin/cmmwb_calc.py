"""The cmmwb LibreOffice Calc add-in: a Python UNO component that gives Calc the functions of
the xlwings add-in (``cmmwb.xlfuncs.udf``) under the same names, so the ``Live_addin`` sheets of the
large workbooks compute live in LibreOffice.

This file runs inside LibreOffice's own Python (on Debian ``/usr/bin/python3`` with
``python3-uno``), not in cmmwb's environment.  The extension ships the core as ``cmmwb.xlfuncs``
in its ``pythonpath/`` folder (LibreOffice puts that folder on ``sys.path`` for the components beside
it); numpy comes from that Python (``apt-get install python3-numpy``).  Every function converts
the cell values Calc passes (tuples of rows; numbers as float, text as str, empty cells None) and
calls the ``cmmwb.xlfuncs.udf`` function of the same name, so both add-ins run the same code.

The interface ``org.cmmwb.calc.XCmmwb`` (``XCmmwb.idl``, type library ``XCmmwb.rdb``) spells the
methods in capitals (UNOIDL forbids ``_`` before a lower-case letter); Calc matches function
names without regard to case.  Install and use: docs/addins.md.
"""

import math

import uno
import unohelper
from com.sun.star.lang import IllegalArgumentException, XServiceInfo, XServiceName
from com.sun.star.sheet import XAddIn, XCompatibilityNames

try:
    from org.cmmwb.calc import XCmmwb
except ImportError:  # unopkg registers the component before it activates the type library
    class XCmmwb:
        """Stands in for the interface while ``unopkg add`` only reads the implementation name."""

IMPLEMENTATION = "org.cmmwb.calc.CmmwbAddIn"
VERSION = "@VERSION@"  # replaced by generator/oxt.py when it packs the extension
SERVICES = ("com.sun.star.sheet.AddIn", IMPLEMENTATION)

#: function (the Excel name) -> (argument names, description); the order of XCmmwb.idl
FUNCTIONS = {
    "cmm_version": ((), "Version of the cmmwb core that the add-in runs"),
    "cmm_v_block": (("factor", "points_rows", "points_cols", "probes", "params"),
                    "Block of V_X,factor (um^2), Forbes 2025 eq. (28)"),
    "cmm_v_et": (("points_rows", "points_cols", "probes", "params"), "V_ET block (um^2), Forbes 2025 eq. (21)"),
    "cmm_v_er": (("points_rows", "points_cols", "probes", "params"),
                 "V_ER block (um^2), Forbes 2025 eqs. (24)-(25)"),
    "cmm_v_p": (("points_rows", "points_cols", "probes", "params"), "V_P block (um^2), Forbes 2025 eqs. (26)-(27)"),
    "cmm_pair_block": (("factor", "point_i", "point_j", "probes", "params"),
                       "3 x 3 block V_ii + V_jj - V_ij - V_ji (um^2), Forbes 2025 eq. (29)"),
    "cmm_pair_blocks": (("factor", "points", "from_ids", "to_ids", "probes", "params"),
                        "Per distance the 3 x 3 pair block of V_X,factor in one row (um^2), eq. (29)"),
    "cmm_distance": (("point_i", "point_j", "probes", "params"),
                     "d_mm, u_um and u_R ... u_P, u_W of one distance, Forbes 2025 eqs. (29)-(30)"),
    "cmm_distances": (("points", "from_ids", "to_ids", "probes", "params"),
                      "Per distance d_mm, u_um and u_R ... u_P, u_W, Forbes 2025 eqs. (29)-(30)"),
    "cmm_feature": (("element", "points", "probes", "params", "circle_plane", "weights", "axis_hint",
                     "reference_mm"),
                    "Fitted element: name, value, u, u_R ... u_P, u_W per parameter (Forbes 2022; 2025 5.6)"),
    "cmm_feature_va": (("element", "points", "probes", "params", "factor", "circle_plane", "weights",
                        "axis_hint", "reference_mm"),
                       "V_A of the fitted parameters for one factor or X (G V_X G^T)"),
}


def _udf():
    from cmmwb.xlfuncs import udf  # imported on first use: LibreOffice starts faster
    return udf


def _arg(value):
    """A Calc argument as xlwings would pass it: ranges as lists of rows, void as None."""
    if isinstance(value, tuple):
        return [list(r) if isinstance(r, tuple) else [r] for r in value]
    if hasattr(value, "value") and type(value).__name__ == "Any":  # pragma: no cover
        return _arg(value.value)
    return value


def _cell(v):
    if isinstance(v, str):
        return v
    try:
        x = float(v)
    except (TypeError, ValueError):
        return str(v)
    return x if math.isfinite(x) else "#NUM!"


def _result(value):
    """A result as a tuple of rows for Calc."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        return ((_cell(value),),)
    if value and not isinstance(value[0], (list, tuple)):
        value = [value]
    return tuple(tuple(_cell(c) for c in row) for row in value)


class CmmwbAddIn(unohelper.Base, XCmmwb, XAddIn, XCompatibilityNames, XServiceName, XServiceInfo):
    def __init__(self, ctx, *args):
        self.ctx = ctx
        self.locale = None

    # -- the functions ----------------------------------------------------------------------
    def _call(self, name, *args):
        try:
            return _result(getattr(_udf(), name)(*(_arg(a) for a in args)))
        except Exception as e:  # shown as an error value in the cell
            raise IllegalArgumentException(f"{name}: {e}", self, 0) from None

    def CMM_VERSION(self):
        return f"cmmwb {VERSION} (LibreOffice add-in)"

    def CMM_V_BLOCK(self, factor, rows, cols, probes, params):
        return self._call("cmm_v_block", factor, rows, cols, probes, params)

    def CMM_V_ET(self, rows, cols, probes, params):
        return self._call("cmm_v_et", rows, cols, probes, params)

    def CMM_V_ER(self, rows, cols, probes, params):
        return self._call("cmm_v_er", rows, cols, probes, params)

    def CMM_V_P(self, rows, cols, probes, params):
        return self._call("cmm_v_p", rows, cols, probes, params)

    def CMM_PAIR_BLOCK(self, factor, pi, pj, probes, params):
        return self._call("cmm_pair_block", factor, pi, pj, probes, params)

    def CMM_PAIR_BLOCKS(self, factor, points, from_ids, to_ids, probes, params):
        return self._call("cmm_pair_blocks", factor, points, from_ids, to_ids, probes, params)

    def CMM_DISTANCE(self, pi, pj, probes, params):
        return self._call("cmm_distance", pi, pj, probes, params)

    def CMM_DISTANCES(self, points, from_ids, to_ids, probes, params):
        return self._call("cmm_distances", points, from_ids, to_ids, probes, params)

    def CMM_FEATURE(self, element, points, probes, params, circle_plane, weights, axis_hint, reference_mm):
        return self._call("cmm_feature", element, points, probes, params, circle_plane, weights, axis_hint,
                          reference_mm)

    def CMM_FEATURE_VA(self, element, points, probes, params, factor, circle_plane, weights, axis_hint,
                       reference_mm):
        return self._call("cmm_feature_va", element, points, probes, params,
                          "X" if factor in (None, "") else factor, circle_plane, weights, axis_hint,
                          reference_mm)

    # -- XAddIn: names and descriptions shown by the function wizard --------------------------
    def getProgrammaticFuntionName(self, display_name):
        name = display_name.lower()
        return name.upper() if name in FUNCTIONS else ""

    def getDisplayFunctionName(self, programmatic_name):
        name = programmatic_name.lower()
        return name if name in FUNCTIONS else ""

    def getFunctionDescription(self, programmatic_name):
        return FUNCTIONS.get(programmatic_name.lower(), ((), ""))[1]

    def getDisplayArgumentName(self, programmatic_name, argument):
        args = FUNCTIONS.get(programmatic_name.lower(), ((), ""))[0]
        return args[argument] if 0 <= argument < len(args) else ""

    def getArgumentDescription(self, programmatic_name, argument):
        return self.getDisplayArgumentName(programmatic_name, argument)

    def getProgrammaticCategoryName(self, programmatic_name):
        return "Add-In"

    def getDisplayCategoryName(self, programmatic_name):
        return "Add-In"

    # -- XCompatibilityNames: the names in Excel files ------------------------------------------
    def getCompatibilityNames(self, programmatic_name):
        """The name Excel files use (Calc compiles the formulas of .xlsx files with these names
        for the en-US locale); without it Calc shows #NAME? for cmm_...() in a workbook."""
        name = programmatic_name.lower()
        if name not in FUNCTIONS:
            return ()
        out = []
        for lang, country in (("en", "US"), ("en", "")):
            entry = uno.createUnoStruct("com.sun.star.sheet.LocalizedName")
            entry.Locale = uno.createUnoStruct("com.sun.star.lang.Locale", lang, country, "")
            entry.Name = name.upper()
            out.append(entry)
        return tuple(out)

    # -- XLocalizable, XServiceName, XServiceInfo ---------------------------------------------
    def setLocale(self, locale):
        self.locale = locale

    def getLocale(self):
        return self.locale or uno.createUnoStruct("com.sun.star.lang.Locale")

    def getServiceName(self):
        return IMPLEMENTATION

    def getImplementationName(self):
        return IMPLEMENTATION

    def supportsService(self, name):
        return name in SERVICES

    def getSupportedServiceNames(self):
        return SERVICES


g_ImplementationHelper = unohelper.ImplementationHelper()
g_ImplementationHelper.addImplementation(CmmwbAddIn, IMPLEMENTATION, SERVICES)
