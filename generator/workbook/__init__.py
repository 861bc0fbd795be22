"""The workbook machinery every task kind shares: cell references and formulas (``xlref``), the
workbook writer and its styles (``book``), the hidden task sheet (``tasksheet``), reading a filled-in
workbook back (``readback``), cached values (``cache``), recalculation (``recalc``), safe reading
of untrusted files (``safe_xlsx``, ``guarded``), atomic output (``atomic``), PDF printing (``pdf``)
and the common plots (``plots``).  It imports no task kind."""
