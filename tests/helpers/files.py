"""Bad input: one clear message naming the file, exit status 2, no traceback."""

from __future__ import annotations


def assert_clear_failure(code: int, err: str, file_name: str, words: list[str]) -> None:
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err and "internal error" not in err, err
    assert err.startswith("cmmwb: error: ") and file_name in err, err
    for w in words:
        assert w in err, f"{w!r} not in: {err}"
