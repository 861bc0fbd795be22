"""xlfuncs: the numerical core of cmmwb (numpy only, no spreadsheet knowledge).

Modules: ``pointcloud`` (Forbes 2025 V_X and distances), ``budget`` (Wojtyla/Plowucha 2023),
``features`` (Forbes 2022 fits and sensitivities), ``diagnose`` (mismatch locator), ``udf``
(xlwings add-in functions).
"""
