"""xlfuncs: the numerical core of cmmwb (numpy only, no spreadsheet knowledge).

Modules: ``model`` (the six-factor model of Forbes 2025, defined once), ``pointcloud`` (V_X and
distances), ``blocked`` and ``lowrank`` (the same without forming V_X), ``budget``
(Wojtyla/Plowucha 2023), ``features`` and ``partial`` (Forbes 2022 fits, sensitivities,
partial-feature approximations), ``characteristics`` (several features, one V_X), ``montecarlo``
(JCGM 101 comparison), ``locator`` (the mismatch locator: recordings, effects, simulate,
diagnose), ``calibrate`` (REML of the hyper-parameters), ``distributed`` (Dask), ``udf`` (the
add-in functions); docs/developing.md has them all.

Installed as ``cmmwb.xlfuncs`` (``cmmwb`` is a namespace package, ``pyproject.toml``); imported by
its folder name from a checkout, ``xlfuncs.x`` is made the very module ``cmmwb.xlfuncs.x``
(``checkout.py``).
"""

if __name__ == "xlfuncs":       # a checkout's folder, imported by its own name (also by generator/__init__.py)
    # the checkout's own file, standard library only: without cmmwb installed, its message says to install it
    from .checkout import alias

    alias(__name__)
