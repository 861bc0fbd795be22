"""A small run of the rate benchmark (bench/diagnose_benchmark.py --quick 20): 20 data sets with a
concealed planted effect (the first edition's scenarios, spread over every concealment), 20 null
sets, 2 aliased designs; the second edition's candidates: tests/locator/test_diagnose_new_candidates.py.  The full
benchmark (about 500 sets) writes bench/results/diagnose_rates.md."""

import importlib.util
import json
import sys

from tests.helpers import ROOT


def test_quick_benchmark_names_the_planted_effects_and_stays_quiet_on_noise(tmp_path):
    spec = importlib.util.spec_from_file_location("diagnose_benchmark", ROOT / "bench" / "diagnose_benchmark.py")
    bench = importlib.util.module_from_spec(spec)
    sys.modules["diagnose_benchmark"] = bench          # dataclasses look their module up
    spec.loader.exec_module(bench)
    assert bench.main(["--quick", "20", "--json", "--out", str(tmp_path)]) == 0
    sets = json.loads((tmp_path / "diagnose_benchmark_quick20.json").read_text())["sets"]
    effect = [s for s in sets if s["category"] not in ("null", "aliased")]
    null = [s for s in sets if s["category"] == "null"]
    aliased = [s for s in sets if s["category"] == "aliased"]
    assert len(effect) == 20 and len(null) == 20
    assert {s["category"] for s in effect} == {"small", "subset", "aliased-unless", "masked"}
    ok = [(s["chosen"][:1] == list(s["planted"])) if len(s["planted"]) == 1
          else all(p in s["chosen"] for p in s["planted"]) for s in effect]
    assert sum(ok) >= 19
    within = [v for s in effect for v in s["within_3u"].values()]
    assert sum(within) >= len(within) - 1
    assert sum(s["mismatch"] for s in null) <= 1
    assert all(s["alias_reported"] for s in aliased)
    assert "named first" in (tmp_path / "diagnose_rates_quick20.md").read_text()
