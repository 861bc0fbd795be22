"""The look of every generated workbook, in one place: fills that tell a reader what a cell is
(input, inherited default, value computed by the core), header and title fonts, the box border,
and the display formats by meaning (the cells keep full precision; only the display changes).
:class:`generator.workbook.book.Book` applies them; writers take formats from here.
"""

from __future__ import annotations

from openpyxl.styles import Border, Font, PatternFill, Side

INPUT_FILL = PatternFill("solid", fgColor="FFF2CC")      # pale yellow: type here
#: pale green: an input that inherits a default by formula (e.g. ``=sigma_P0_um``); typing a
#: number overrides it for this cell only
DEFAULT_FILL = PatternFill("solid", fgColor="E2EFDA")
VALUE_FILL = PatternFill("solid", fgColor="EDEDED")      # grey: values computed by the core
HEADER_FONT = Font(bold=True)
TITLE_FONT = Font(bold=True, size=14)
INPUT_FONT = Font(color="1F4E79")
THIN = Side(style="thin", color="BFBFBF")
BOX = Border(left=THIN, right=THIN, top=THIN, bottom=THIN)
NUMBER_FORMAT = "0.000000"
#: display formats by meaning (the cells keep full precision; only the display changes)
FMT_MM = "0.0000"          # lengths and coordinates in mm (0.1 µm resolution)
FMT_COORD = "0.0#####"     # measured coordinates in mm: as entered, to 1 nm (General showed 1E-16)
FMT_UM = "0.0000"          # uncertainties in µm (3-4 significant digits at 0.1-10 µm)
#: quantities spanning decades (matrix entries, p-values); an exact zero (and the -0 a product
#: of zeros gives in LibreOffice) prints as 0, not as -0.000E+00
FMT_SCI = "0.000E+00;-0.000E+00;0"
