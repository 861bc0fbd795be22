"""The mismatch locator run on recordings (``docs/recordings.md``): the simulation's model from a
task file (:func:`load_model`), a diagnosis into a folder (:func:`run_diagnose`:
``diagnosis.json``, ``diagnosis.xlsx`` with the native refit, PNG plots, all or nothing), and the
concealed-effect demonstration of ``cmmwb demo`` (:func:`demo`).  The commands are
:mod:`generator.cli.diagnose` and :mod:`generator.cli.simulate`.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path

from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.distributed import get_backend
from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.recordings import RecordingsError, parse_recordings, write_recordings
from cmmwb.xlfuncs.memory import ResourceError, check_diagnose_fits, check_records_fit
from cmmwb.xlfuncs.model import MPE1  # Forbes 2025 Table 3, MPE1: the model of the demonstrations
from cmmwb.xlfuncs.model.hyperparameters import in_table

from .. import __version__
from ..errors import InputError, model_errors_named
from ..workbook.atomic import Staging
from ..workbook.provenance import provenance

# -- the model ----------------------------------------------------------------------------------

def load_model(task: str | None, sigma_um: float | None, *, default_mpe1: bool = False) -> tuple[dg.Model, str]:
    from ..taskcloud import read_parameters, read_probes
    from ..taskfile import naming_lines, read_toml
    from ..taskworkpiece import read_workpiece

    if task is not None and sigma_um is not None:
        raise InputError("give either --task or --sigma-um, not both")
    if sigma_um is not None:
        if not math.isfinite(sigma_um) or sigma_um <= 0:
            raise InputError(f"--sigma-um must be a positive number, got {sigma_um!r}")
        return dg.Model(pc.Parameters(sigma_R_um=sigma_um)), f"sigma_R_um = {sigma_um:g} µm (--sigma-um)"
    if task is None:
        if default_mpe1:
            return dg.Model(MPE1), "Forbes 2025 Table 3 MPE1"
        raise InputError("give the simulation: --task TASK.toml or --sigma-um S")
    path = Path(task)
    doc = read_toml(path)
    with naming_lines(path):
        params = read_parameters(path, doc)
        probes = read_probes(path, doc)
        part = read_workpiece(path, doc)        # the artefact's temperature (the factor W)
    with model_errors_named(path, "[[probes]]"):
        for p in probes:
            p.resolved(params)
    if all(getattr(params, k) == 0 for k in params.SIGMAS):
        raise InputError("every standard deviation is zero: the simulation predicts the records exactly; "
                         "set sigma_R_um (at least)", file=path, where="[parameters]")
    if part is None:
        return dg.Model(params, probes, "probes" in doc), str(path)
    return dg.Model(replace(params, **part.u), probes, "probes" in doc, part.workpiece), str(path)


def read_recordings(path: Path):
    """The recordings file ``path`` parsed (docs/recordings.md); a problem names its line."""
    from ..workbook.guarded import read_text

    text = read_text(path, "recordings")   # a regular file within its size cap, UTF-8
    lines = text.count("\n") + (not text.endswith("\n")) - text.count("\n#") - text.startswith("#")
    try:
        check_records_fit(max(lines - 1, 0))       # before parsing: the data lines are the records
    except ResourceError as e:
        raise InputError(str(e), file=path) from None
    try:
        return parse_recordings(text)
    except RecordingsError as e:
        raise InputError(e.message, file=path, where=e.where) from None


def run_diagnose(rec_path: Path, model: dg.Model, out_dir: Path, *, alpha: float = 0.01, plots: bool = True,
                 workbook: bool = True, source: str = "", rec=None, task_label: str = "",
                 force: bool = False, exact: bool = False, alpha_name: float | None = None,
                 warnings: list[str] | tuple[str, ...] = (), task_path: Path | None = None) -> tuple[dict, list[Path]]:
    """Diagnose ``rec_path`` into ``out_dir`` (all or nothing); returns the JSON and the files.
    ``exact``: the dense record covariance whatever the size (no structured approximation);
    ``task_path``: the task file of the simulation (its SHA-256 in ``provenance``), or None."""
    from ..taskfile import read_toml
    from .book import write_book
    from .plots import write_plots

    rec_path = Path(rec_path)
    if not (0.0 < alpha < 1.0):
        raise InputError(f"--alpha must be between 0 and 1, got {alpha!r}")
    if alpha_name is not None and not (0.0 < alpha_name <= alpha):
        raise InputError(f"--alpha-name must be above 0 and at most --alpha ({alpha:g}), got {alpha_name!r}")
    rec = read_recordings(rec_path) if rec is None else rec
    structured = dg.uses_structured(rec, model, False if exact else None)
    try:
        check_diagnose_fits(rec.kind, rec.n, 2 if getattr(rec, "planar", False) else 3,
                            structured=structured)
    except ResourceError as e:
        raise InputError(str(e), file=rec_path) from None
    with model_errors_named(task_label or rec_path):
        try:
            backend = get_backend() if structured and rec.kind == "length" else None
            try:
                diag = dg.diagnose(rec, model, alpha, structured=False if exact else None, alpha_name=alpha_name,
                                   backend=backend)
            finally:
                if backend is not None:
                    backend.close()
        except RecordingsError as e:     # a ModelError too, named by the recordings' line
            raise InputError(e.message, file=rec_path, where=e.where) from None
    result = diag.to_json()
    prov = provenance(task_path, read_toml(task_path) if task_path is not None else None, read=[rec_path])
    result = {"name": "diagnosis", "version": __version__,
              "recordings": rec_path.name, "simulation": task_label, **result,
              "warnings": [*warnings, *(f"{rec_path}, {n}" for n in getattr(rec, "notes", ()))],
              "provenance": prov}
    with Staging(out_dir, force=force) as tmp:
        (tmp / "diagnosis.json").write_text(json.dumps(result, indent=1, ensure_ascii=False, allow_nan=False)
                                            + "\n", encoding="utf-8")
        made = [tmp / "diagnosis.json"]
        if workbook:
            made.append(write_book(diag, tmp / "diagnosis.xlsx", params=model.params, source=rec_path.name,
                                   provenance=prov))
        if plots:
            made += write_plots(diag, tmp)
    return result, [Path(out_dir) / p.name for p in made]


# -- the demonstration ------------------------------------------------------------------------------

DEMO_PROBES = (pc.Probe("P1", (0.0, 0.0, -50.0)),)


def task_toml(params: pc.Parameters, probes, name: str, note: str) -> str:
    lines = [f"# {note}", "[task]", 'kind = "pointcloud"', f'name = "{name}"', "", "[parameters]"]
    for k in in_table("parameters"):
        lines.append(f"{k} = {getattr(params, k)!r}")
    for p in probes:
        lines += ["", "[[probes]]", f'id = "{p.id}"',
                  "offset_mm = [" + ", ".join(repr(float(v)) for v in p.offset_mm) + "]"]
    return "\n".join(lines) + "\n"


def planted_text(planted: dict) -> str:
    """The planted effects of a simulation, each with its unit (docs/recordings.md section 4):
    ``squareness_xy = 9 µrad``, ``probe_qualification = P2: (0.5, 0, 0) µm``, ``periodic_x = 0.5,
    -0.3 µm, period 40 mm``; ``nothing`` when none."""
    from cmmwb.xlfuncs.locator.effects import BY_NAME

    def numbers(v) -> str:
        return ", ".join(f"{x:g}" for x in v)

    out = []
    for name, value in planted.items():
        unit = BY_NAME[name].unit.replace("um", "µm").replace("urad", "µrad")
        if isinstance(value, dict):             # per probe: probe_qualification, probe_lobing
            text = "; ".join(f"{pid}: ({numbers(v)}) {unit}" for pid, v in value.items())
        elif name.startswith("periodic_"):      # a, b (µm), period (mm)
            text = f"{numbers(value[:2])} {unit}, period {value[2]:g} mm"
        elif isinstance(value, (list, tuple)):
            text = f"({numbers(value)}) {unit}"
        else:
            text = f"{value:g} {unit}"
        out.append(f"{name} = {text}")
    return ", ".join(out) or "nothing"


def demo(out_dir: Path, verbose: bool = True, force: bool = False) -> list[Path]:
    """Two cases into ``out_dir``: a squareness error concealed in an ISO 10360-2 length test
    (no larger in any record than noise reaches anyway, only in the diagonal lengths) found and
    modelled; and a pitch
    error measured with one probe offset, reported as aliased with an x scale error.  The files
    written; ``verbose``: each case's answer and files printed too; ``force``: files edited since
    an earlier demo wrote them are replaced (kept as ``NAME.bak``)."""
    out_dir = Path(out_dir)
    params = MPE1
    model = dg.Model(params, DEMO_PROBES, True)
    files = []
    cases = [
        ("concealed", {"squareness_xy": 9.0}, 3,
         "ISO 10360-2 test (7 positions x 5 lengths x 3), MPE1 model, planted squareness_xy = 9 µrad: "
         "at most 2.5 sigma in any record (what the largest of 105 noise records reaches anyway), "
         "only in the diagonal lengths"),
        ("aliased", {"EBX": 150.0}, 5,
         "the same test with one probe offset (0, 0, -50) mm, planted EBX (pitch of the X carriage) = 150 "
         "µrad/m: it moves the tip like an x scale error of p_z * kappa = -7.5 µm/m (Forbes 2025 section 3.3)"),
    ]
    say = print if verbose else (lambda *_: None)
    say(f"\n[diagnose] mismatch locator demonstrations -> {out_dir}/")
    for name, planted, seed, note in cases:
        t = time.perf_counter()
        L = sm.iso10360(DEMO_PROBES)
        rec = sm.simulate(L, params, planted, seed=seed, temperature_C=20.0)
        case_dir = out_dir / name
        with Staging(case_dir, force=force) as tmp:
            write_recordings(rec, tmp / "recordings.csv",
                             comments=[f"cmmwb demo: {note}", f"planted: {planted}, seed {seed}"])
            (tmp / "task.toml").write_text(task_toml(params, DEMO_PROBES, f"demo_{name}", note), encoding="utf-8")
        result, made = run_diagnose(case_dir / "recordings.csv", model, case_dir, source="demo",
                                    task_label=str(case_dir / "task.toml"), task_path=case_dir / "task.toml",
                                    force=force)
        files += [case_dir / "recordings.csv", case_dir / "task.toml", *made]
        say(f"\n  [{name}] {note}  ({time.perf_counter() - t:.1f} s)")
        say(f"    planted: {planted_text(planted)}")
        say(f"    {result['summary']}")
        for f in [case_dir / "recordings.csv", case_dir / "task.toml", *made]:
            say(f"    -> {f}")
    return files
