"""The mismatch locator (``cmmwb diagnose``): its command (``cli``) and its workbook (``book``)."""
