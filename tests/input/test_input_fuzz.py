"""Property (issue 12): whatever bytes the task file or the points table hold, reading them gives
either a valid task or an InputError (one message, exit status 2) -- never another exception.
The files are fuzzed at the reader level (no workbook is written), so many examples run fast;
tests/input/test_build_property.py covers whole builds."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from cmmwb.generator.build import load_task
from cmmwb.generator.errors import InputError

from tests.helpers import BAD_FILES

sys.path.insert(0, str(BAD_FILES))
from make_bad_files import POINTCLOUD_CSV, POINTCLOUD_TASK  # noqa: E402

FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

any_text = st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=12)
numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["1e12", "-1e15", "100000", "100000.0000001", "1,5", "0x10", "1_000", "", " ", "nan",
                     "9" * 400, "1e309", "-0", "\u0661\u0662", "\ufeff1"]),
    st.integers(min_value=-10**30, max_value=10**30).map(str),
)
fields = st.one_of(numbers, any_text, st.sampled_from(["P1", "P2", "A", '"a,b"', '"', "\x00", "#"]))
headers = st.one_of(
    st.just("id,x,y,z,nx,ny,nz,probe"),
    st.lists(st.sampled_from(["id", "x", "y", "z", "x_mm", "nx", "ny", "nz", "probe", "w", ""]),
             min_size=0, max_size=10).map(",".join),
)


@st.composite
def csv_files(draw) -> bytes:
    if draw(st.booleans()):   # a real table with random defects
        lines = POINTCLOUD_CSV.splitlines()
        for _ in range(draw(st.integers(0, 3))):
            k = draw(st.integers(0, len(lines) - 1))
            cells = lines[k].split(",")
            j = draw(st.integers(0, len(cells)))
            action = draw(st.sampled_from(["replace", "insert", "delete"]))
            if action == "replace" and j < len(cells):
                cells[j] = draw(fields)
            elif action == "insert":
                cells.insert(j, draw(fields))
            elif cells:
                cells.pop(min(j, len(cells) - 1))
            lines[k] = ",".join(cells)
        text = "\n".join(lines) + "\n"
    else:                     # anything at all under a plausible header
        rows = draw(st.lists(st.lists(fields, max_size=10).map(",".join), max_size=6))
        text = "\n".join([draw(headers), *rows])
    raw = text.encode("utf-8")
    if draw(st.booleans()):
        raw = draw(st.sampled_from([b"\xef\xbb\xbf", b"", b"\xff\xfe", b"\x00"])) + raw
    return raw


toml_values = st.one_of(
    numbers, st.sampled_from(['"x"', "true", "[1, 2]", "{a = 1}", "[" * 30 + "]" * 30, '"\\u0000"', "inf",
                              "1979-05-27", '"""a\nb"""', "[[1]]", "-nan", "0o777", "1e400"]),
)


@st.composite
def toml_files(draw) -> bytes:
    text = POINTCLOUD_TASK
    if draw(st.booleans()):   # change values of the real task
        keys = ["sigma_R_um", "sigma_S_ppm", "sigma_PQ_um", "lambda_ET_mm", "offset_mm", "name", "kind", "file"]
        for _ in range(draw(st.integers(1, 3))):
            key = draw(st.sampled_from(keys))
            lines = text.splitlines()
            hits = [i for i, ln in enumerate(lines) if ln.startswith(key + " =")]
            if hits:
                lines[hits[0]] = f"{key} = {draw(toml_values)}"
            text = "\n".join(lines) + "\n"
    else:                     # cut, duplicate or insert random text
        k = draw(st.integers(0, len(text)))
        text = text[:k] + draw(st.sampled_from(["", "\n[task]\n", "\x00", "=", "[[probes]]\n", "\ufeff"])) + \
            draw(any_text) + text[k + draw(st.integers(0, 40)):]
    raw = text.encode("utf-8", "surrogatepass")
    if draw(st.booleans()):
        raw = draw(st.sampled_from([b"\xef\xbb\xbf", b"\xfe\xff", b"\xc0"])) + raw
    return raw


def _outcome(task_path: Path) -> str:
    try:
        kind, _mod, _doc, task = load_task(task_path)
    except InputError as e:
        msg = str(e)
        assert msg.strip(), msg
        return "error"
    assert kind == "pointcloud"
    X = task.cloud.X_mm
    if X is not None:   # a valid task holds only finite coordinates inside the machine range
        assert all(math.isfinite(v) and abs(v) <= 1e5 for v in X.ravel())
    return "task"


@FUZZ
@given(raw=csv_files())
def test_any_points_table_gives_a_task_or_an_input_error(tmp_path_factory, raw):
    tmp = tmp_path_factory.mktemp("csv")
    (tmp / "small.toml").write_text(POINTCLOUD_TASK)
    (tmp / "small.csv").write_bytes(raw)
    event(_outcome(tmp / "small.toml"))


@FUZZ
@given(raw=toml_files())
def test_any_task_file_gives_a_task_or_an_input_error(tmp_path_factory, raw):
    tmp = tmp_path_factory.mktemp("toml")
    (tmp / "small.toml").write_bytes(raw)
    (tmp / "small.csv").write_text(POINTCLOUD_CSV)
    event(_outcome(tmp / "small.toml"))
