"""The loop a lab runs (docs/validate.md section 6), end to end on a simulated machine:
verification recordings -> ``cmmwb calibrate`` -> the fitted task -> ``cmmwb validate`` on
workpieces not used in the fit -> "the model holds", or the named cause and the next step.

The machine (:data:`TRUTH`) is worse than the type-B model a lab starts from (Forbes 2025
Table 3 MPE1): its repeatability and its translation errors are larger.  Its verification
recordings are an ISO 10360-2 length test with three styli and a ball plate in four passes; the
validation workpieces are step gauges (lengths with their probed points), rings and spheres
(fitted characteristics), which the fit never saw.  With the starting model the validation does
not hold; with the fitted one it does.

The recordings and the validation set are two draws of the machine's model (the simulator does
not keep one realization of the machine's error functions across them): the validation checks
what the fitted hyper-parameters claim about the machine's errors, as U does.  Used by
``cmmwb demo`` and ``tests/validation/test_validate_loop.py``.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.recordings import write_recordings
from cmmwb.xlfuncs.model import MPE1
from cmmwb.xlfuncs.model.hyperparameters import in_table

from ..workbook.atomic import Staging
from .sets import FEATURES, LENGTHS, write_set

#: the simulated machine: MPE1 with a repeatability of 0.35 µm and translation errors of 0.5 µm
TRUTH = replace(MPE1, sigma_R_um=0.35, sigma_ET_um=0.5, lambda_ET_mm=150.0)
PROBES = (pc.Probe("P1", (0.0, 0.0, -50.0)), pc.Probe("P2", (150.0, 0.0, -50.0)), pc.Probe("P3", (0.0, 150.0, -50.0)))
WORKPIECES = ["stepgauge", "ring", "sphere"]
SEEDS = {"iso": 11, "plate": 12, "validation": 13}


def with_parameters(task: Path, params: dict, out: Path, note: str) -> Path:
    """The task ``task`` with ``params`` as its [parameters] (its points file beside it)."""
    import tomllib

    import tomli_w

    doc = tomllib.loads(task.read_text(encoding="utf-8"))
    doc["parameters"] = {k: float(params[k]) for k in in_table("parameters")}
    doc["task"]["notes"] = list(doc["task"].get("notes", [])) + [note]
    out.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return out


def prepare(out_dir: Path, force: bool = False) -> dict[str, Path]:
    """The loop's inputs into ``out_dir``: the verification recordings (``iso.csv``,
    ``plate.csv``), the validation set (``validation/``: its tasks with the machine's truth,
    ``results.csv``) and the lab's starting tasks with MPE1 (``start_lengths.toml``,
    ``start_features.toml``); ``force``: files edited since an earlier run wrote them are replaced
    (kept as ``NAME.bak``)."""
    out_dir = Path(out_dir)
    iso = sm.simulate(sm.iso10360(PROBES), TRUTH, {}, seed=SEEDS["iso"])
    plate = sm.simulate(sm.ballplate(PROBES, passes=4), TRUTH, {}, seed=SEEDS["plate"])
    with Staging(out_dir, force=force) as tmp:
        write_recordings(iso, tmp / "iso.csv", comments=["cmmwb demo (validation loop): ISO 10360-2 lengths, "
                                                         "three styli, the simulated machine"])
        write_recordings(plate, tmp / "plate.csv", comments=["cmmwb demo (validation loop): ball plate, four "
                                                             "passes, the simulated machine"])
    write_set(out_dir / "validation", WORKPIECES, TRUTH, PROBES, {}, SEEDS["validation"], 2,
              "the simulated machine of generator/validation/loop.py", force=force)
    mpe1 = {k: float(getattr(MPE1, k)) for k in in_table("parameters")}
    note = "the lab's starting model: Forbes 2025 Table 3 MPE1 (type B)"
    files = {"iso": out_dir / "iso.csv", "plate": out_dir / "plate.csv",
             "results": out_dir / "validation" / "results.csv",
             "start_lengths": with_parameters(out_dir / "validation" / f"{LENGTHS}.toml", mpe1,
                                              out_dir / "validation" / "start_lengths.toml", note),
             "start_features": with_parameters(out_dir / "validation" / f"{FEATURES}.toml", mpe1,
                                               out_dir / "validation" / "start_features.toml", note)}
    return files


def run_loop(out_dir: Path, *, workbook: bool = True, profiles: str = "no", force: bool = False) -> dict:
    """The loop into ``out_dir``: validate the starting model, calibrate on the verification
    recordings, validate the fitted model; returns the three results.  ``profiles``: those of
    ``cmmwb calibrate`` (``no`` by default here: they take five times the fit, about 60 s); ``force``: as :func:`prepare`'s."""
    from ..calibration.run import run_calibrate
    from ..diagnosis.run import load_model
    from .run import run_validate

    out_dir = Path(out_dir)
    f = prepare(out_dir, force=force)
    before, _ = run_validate(f["results"], [f["start_lengths"], f["start_features"]], out_dir / "validate_start",
                             workbook=workbook, force=force)
    model, label = load_model(str(f["start_lengths"]), None)
    cal, _ = run_calibrate([f["iso"], f["plate"]], model, out_dir / "calibrate", task_path=f["start_lengths"],
                           task_label=label, workbook=workbook, profiles=profiles, force=force)
    fitted_lengths = out_dir / "calibrate" / "fitted.toml"
    fitted_features = with_parameters(f["start_features"], cal["fitted_parameters"],
                                      out_dir / "validation" / "fitted_features.toml",
                                      "[parameters] of calibrate/fitted.toml (cmmwb calibrate on iso.csv, plate.csv)")
    after, _ = run_validate(f["results"], [fitted_lengths, fitted_features], out_dir / "validate_fitted",
                            workbook=workbook, force=force)
    # the truth where it differs from MPE1 (sigma_R_um, sigma_ET_um, lambda_ET_mm)
    summary = {"truth": {k: float(getattr(TRUTH, k)) for k in in_table("parameters")
                         if getattr(TRUTH, k) != getattr(MPE1, k)},
               "before": before["verdict"], "calibration": cal["summary"], "after": after["verdict"]}
    (out_dir / "loop.json").write_text(json.dumps(summary, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return {"before": before, "calibration": cal, "after": after}


def demo(out_dir: Path, verbose: bool = True, force: bool = False) -> list[Path]:
    """``cmmwb demo``: the loop into ``out_dir``, with what each step says when ``verbose``;
    returns the workbooks written."""
    import time

    t = time.perf_counter()
    say = print if verbose else (lambda *a, **k: None)
    say(f"\n[validate] the loop a lab runs: recordings -> calibrate -> fitted task -> validate -> {out_dir}/")
    r = run_loop(out_dir, force=force)
    say(f"  the starting model (MPE1): {r['before']['summary']}")
    say(f"  calibrate (iso.csv, plate.csv): {r['calibration']['summary']}")
    say(f"  the fitted model: {r['after']['summary']}  ({time.perf_counter() - t:.1f} s)")
    return sorted(Path(out_dir).rglob("*.xlsx"))
