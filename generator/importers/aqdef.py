"""Q-DAS AQDEF (``.dfq``, or ``.dfd`` description + ``.dfx`` values): characteristic values.

A small reader of the K-field subset cmmwb can use, written here instead of depending on
``aqdefreader`` (PyPI 1.3.0, Apache-2.0): that package imports pandas, chardet and
python-dateutil without declaring them, prints warnings to stdout, reads no ``.dfd``/``.dfx``
pairs and has no size guard (docs/import.md).

Read: ``K0100`` (number of characteristics), ``K1001``/``K1002`` (part), per characteristic
``K2001`` (number), ``K2002`` (description), ``K2004`` (0 variable, 1 attribute), ``K2101``
(nominal), ``K2110``/``K2111`` (limits), ``K2142`` (unit), and values as ``K0001/i`` lines or
as value lines (fields separated by 0x0F per characteristic, 0x14 within one).

What cmmwb needs from a length: length recordings (recordings.md 1a) need the coordinates of the
two probed points (x1..z2) besides reference and measured length.  AQDEF carries characteristic
values, not point coordinates, so the import stops with a message that lists what the file holds
and what is missing.  Nothing is written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ..workbook.guarded import read_bytes


@dataclass
class Characteristic:
    index: int
    fields: dict = field(default_factory=dict)
    values: list[float] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.fields.get("K2002") or self.fields.get("K2001") or f"#{self.index}"


def _decode(raw: bytes) -> str:
    for enc in ("utf-8", "cp1252"):
        try:
            return raw.decode(enc)
        except UnicodeDecodeError:
            continue
    return raw.decode("latin-1")


#: K2142 units that are lengths (AQDEF writes the unit as text; any letter case), in mm
LENGTH_UNITS_MM = {"nm": 1e-6, "µm": 1e-3, "μm": 1e-3, "um": 1e-3, "mm": 1.0, "cm": 10.0, "dm": 100.0,
                   "m": 1000.0, "in": 25.4, "inch": 25.4, '"': 25.4}


def is_length_unit(unit: str | None) -> bool:
    """A K2142 unit text names a length (``cm`` does; a missing unit does not)."""
    return unit is not None and unit.strip().lower().replace("micron", "µm") in LENGTH_UNITS_MM


def _number(text: str) -> float | None:
    try:
        return float(text.strip().replace(",", "."))
    except ValueError:
        return None


def read_aqdef(paths: list[Path]) -> tuple[dict, dict[int, Characteristic]]:
    """(part fields, {index: characteristic}) of one AQDEF file or a .dfd + .dfx pair."""
    part: dict = {}
    chars: dict[int, Characteristic] = {}
    for path in paths:
        for lineno, line in enumerate(_decode(read_bytes(path, "import")).splitlines(), start=1):
            line = line.rstrip("\r")
            if not line.strip():
                continue
            if line.startswith("K"):
                code, _, value = line.partition(" ")
                key, _, idx = code.partition("/")
                if key.startswith("K1"):
                    part[key] = value.strip()
                elif key.startswith(("K2", "K0001")):
                    i = int(idx) if idx.isdigit() else 1
                    c = chars.setdefault(i, Characteristic(i))
                    if key == "K0001":
                        v = _number(value)
                        if v is None:
                            raise InputError(f"K0001/{i}: {value.strip()!r} is not a number", file=path,
                                             where=f"line {lineno}")
                        c.values.append(v)
                    else:
                        c.fields[key] = value.strip()
            else:  # value line: one block per characteristic
                for i, block in enumerate(line.split("\x0f"), start=1):
                    v = _number(block.split("\x14")[0])
                    if v is not None:
                        chars.setdefault(i, Characteristic(i)).values.append(v)
    return part, chars


def import_aqdef(src: Path, out: Path, *, force: bool = False):
    paths = [src]
    if src.suffix.lower() == ".dfd":
        dfx = src.with_suffix(".dfx") if src.with_suffix(".dfx").exists() else src.with_suffix(".DFX")
        if not dfx.exists():
            raise InputError("a .dfd file holds the descriptions only; its values are in the .dfx file "
                             f"of the same name ({src.with_suffix('.dfx').name}), which is missing", file=src)
        paths.append(dfx)
    elif src.suffix.lower() == ".dfx":
        raise InputError("give the .dfd file (descriptions); its .dfx beside it is read with it", file=src)
    part, chars = read_aqdef(paths)
    if not chars:
        raise InputError("no characteristics (no K2xxx fields and no values)", file=src)
    variable = [c for c in chars.values() if c.fields.get("K2004", "0").strip() == "0"]
    lengths = [c for c in variable if is_length_unit(c.fields.get("K2142"))]
    no_unit = [c for c in variable if not c.fields.get("K2142", "").strip()]

    def described(c: Characteristic) -> str:
        unit = c.fields.get("K2142", "").strip()
        text = f"{c.name} ({len(c.values)} values"
        if "K2101" in c.fields:
            text += f", nominal {c.fields['K2101']}" + (f" {unit}" if unit else "")
        return text + ("" if unit else ", no unit: K2142 missing") + ")"

    listing = "; ".join(described(c) for c in chars.values())
    unsaid = (f"; {len(no_unit)} without a unit (no K2142 field: not assumed to be mm)" if no_unit else "")
    raise InputError(
        f"AQDEF holds characteristic values, not point coordinates: {len(chars)} characteristics "
        f"({len(lengths)} variable ones in length units{unsaid}): {listing}. Length recordings "
        "(recordings.md 1a) need x1,y1,z1,x2,y2,z2 of the two probed points of every length, which "
        "AQDEF does not carry; export the points (e.g. as QIF) or write the recordings CSV with the "
        "coordinates from the measurement program", file=src)
