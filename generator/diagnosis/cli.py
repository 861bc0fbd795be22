"""``cmmwb diagnose`` and ``cmmwb simulate`` (``docs/recordings.md``), and the
concealed-effect demonstration of ``cmmwb demo``.

``cmmwb diagnose RECORDINGS.csv --task TASK.toml --out DIR`` (or ``--sigma-um S``) writes
``DIR/diagnosis.json`` (docs/recordings.md section 5), ``DIR/diagnosis.xlsx`` (native refit) and PNG plots, all
or nothing, and prints the plain-language answer.

``cmmwb simulate --layout iso10360 --task TASK.toml --effect squareness_xy=4 --seed 1 --out
rec.csv`` writes recordings of a realistic layout measured by a CMM drawn from the task's model,
with the planted effects.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path


from xlfuncs.locator import diagnose as dg
from xlfuncs import pointcloud as pc
from xlfuncs.locator import simulate as sm
from xlfuncs.errors import ModelError
from xlfuncs.distributed import get_backend
from xlfuncs.memory import ResourceError, check_diagnose_fits
from xlfuncs.locator.recordings import RecordingsError, parse_recordings, write_recordings

from .. import __version__
from ..errors import InputError
from ..workbook.atomic import write_text

#: Forbes 2025 Table 3, MPE1: the model of the demonstrations
MPE1 = dict(sigma_R_um=0.20, sigma_S_ppm=0.7, sigma_Sa_ppm=0.7, sigma_Q_ppm=0.7, sigma_PQ_um=0.20,
            sigma_ET_um=0.2, lambda_ET_mm=200.0, sigma_ER_urad=4.0, lambda_ER_mm=400.0,
            sigma_P0_um=0.10, sigma_P_um=0.10, lambda_P=0.5)


def register(sub) -> None:
    from ..commands import add_command

    s = add_command(sub, "diagnose", "compare recordings with the simulation: where, why, what to add",
                    "Mismatch locator (docs/recordings.md): chi-square of the recordings against the "
                    "simulation's covariance, location of the mismatch, the candidate effects that explain "
                    "it, and the refit. Writes DIR/diagnosis.json, a workbook whose refit uses native "
                    "formulas, and residual plots before and after.",
                    ("cmmwb diagnose stepgauge.csv --task machine.toml --out diag",
                     "cmmwb diagnose plate.csv --sigma-um 0.3 --out diag --alpha 0.001",
                     "cmmwb simulate --layout stepgauge --effect scale_x=2 --out rec.csv && "
                     "cmmwb diagnose rec.csv --sigma-um 0.2 --out d"))
    s.add_argument("recordings", metavar="RECORDINGS.csv",
                   help="recordings CSV (length records: a measured_mm column; point records: x_nom)")
    s.add_argument("--task", metavar="TASK.toml",
                   help="task file whose [parameters] and [[probes]] define the simulation")
    s.add_argument("--sigma-um", type=float, metavar="S",
                   help="instead of --task: a simulation with only repeatability sigma_R_um = S (µm)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    s.add_argument("--alpha", type=float, default=0.01, help="significance level (default: 0.01)")
    s.add_argument("--alpha-name", type=float, default=None, metavar="P",
                   help="adjusted p-value below which an effect is named as the cause (default: alpha/100); "
                        "between it and alpha the best effect is only 'indicated'")
    s.add_argument("--no-plots", action="store_true", help="skip the PNG plots (default: write them)")
    s.add_argument("--no-workbook", action="store_true", help="skip the workbook (default: write it)")
    s.add_argument("--force", action="store_true",
                   help="replace outputs edited since cmmwb wrote them, keeping a backup (default: refuse)")
    s.add_argument("--exact", action="store_true",
                   help="the dense record covariance (exact, memory ~ n^2) even for large point records "
                        "(default: above %d observations the structured operator, error bound in the "
                        "JSON's approximation)" % dg.STRUCTURED_MIN_OBS)
    s.set_defaults(func=cmd_diagnose)

    s = add_command(sub, "simulate", "write recordings of a realistic layout with planted effects",
                    "Recordings measured by a CMM drawn from the task's Forbes 2025 model (or Table 3 "
                    "MPE1 without --task), with planted effects named as in docs/recordings.md section 4.",
                    ("cmmwb simulate --layout iso10360 --out rec.csv",
                     "cmmwb simulate --layout stepgauge --effect squareness_xy=4.1 --seed 7 --out rec.csv",
                     "cmmwb simulate --layout ballplate --effect thermal_expansion=1.5 "
                     "--temperature-C 20,23 --out rec.csv"))
    s.add_argument("--layout", required=True, choices=sm.LAYOUTS,
                   help="what is measured: " + ", ".join(sm.LAYOUTS))
    s.add_argument("--task", metavar="TASK.toml",
                   help="task file: [parameters] and [[probes]] of the simulated CMM (default: Forbes 2025 "
                        "Table 3 MPE1)")
    s.add_argument("--sigma-um", type=float, metavar="S",
                   help="instead of --task: a CMM with only repeatability sigma_R_um = S (µm)")
    s.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                   help="planted effect in the unit of docs/recordings.md section 4, e.g. squareness_xy=4.1, "
                        "probe_qualification=P2:0.5,0,0, offset_drift=0.3,0,0, periodic_x=0.5,-0.3,40 "
                        "(a, b in µm, the period in mm; section 7) (repeatable; default: none)")
    s.add_argument("--seed", type=int, default=1, help="random seed (default: 1)")
    s.add_argument("--temperature-C", default=None, metavar="T|T0,T1",
                   help="artefact temperature: T or T0,T1 (a ramp over the session) in °C "
                        "(default: no temperature column)")
    s.add_argument("--hours", type=float, default=None,
                   help="length of the session in hours (adds time_s; default: no time column)")
    s.add_argument("--repeats", type=int, default=None,
                   help="repetitions (iso10360, stepgauge; default: the layout's own)")
    s.add_argument("--out", required=True, metavar="REC.csv", help="recordings CSV to write")
    s.set_defaults(func=cmd_simulate)


# -- the model ----------------------------------------------------------------------------------

def load_model(task: str | None, sigma_um: float | None, *, default_mpe1: bool = False) -> tuple[dg.Model, str]:
    from ..taskfile import naming_lines, read_parameters, read_probes, read_toml

    if task is not None and sigma_um is not None:
        raise InputError("give either --task or --sigma-um, not both")
    if sigma_um is not None:
        if not math.isfinite(sigma_um) or sigma_um <= 0:
            raise InputError(f"--sigma-um must be a positive number, got {sigma_um!r}")
        return dg.Model(pc.Parameters(sigma_R_um=sigma_um)), f"sigma_R_um = {sigma_um:g} µm (--sigma-um)"
    if task is None:
        if default_mpe1:
            return dg.Model(pc.Parameters(**MPE1)), "Forbes 2025 Table 3 MPE1"
        raise InputError("give the simulation: --task TASK.toml or --sigma-um S")
    path = Path(task)
    doc = read_toml(path)
    with naming_lines(path):
        params = read_parameters(path, doc)
        probes = read_probes(path, doc)
    try:
        for p in probes:
            p.resolved(params)
    except ModelError as e:
        raise InputError(str(e), file=path, where="[[probes]]") from None
    if all(getattr(params, k) == 0 for k in params.SIGMAS):
        raise InputError("every standard deviation is zero: the simulation predicts the records exactly; "
                         "set sigma_R_um (at least)", file=path, where="[parameters]")
    return dg.Model(params, probes, "probes" in doc), str(path)


def _read(path: Path):
    from ..workbook.guarded import read_text

    text = read_text(path, "recordings")   # a regular file within its size cap, UTF-8
    try:
        return parse_recordings(text)
    except RecordingsError as e:
        raise InputError(e.message, file=path, where=e.where) from None


def run_diagnose(rec_path: Path, model: dg.Model, out_dir: Path, *, alpha: float = 0.01, plots: bool = True,
                 workbook: bool = True, source: str = "", rec=None, task_label: str = "",
                 force: bool = False, exact: bool = False, alpha_name: float | None = None,
                 warnings: list[str] | tuple[str, ...] = ()) -> tuple[dict, list[Path]]:
    """Diagnose ``rec_path`` into ``out_dir`` (all or nothing); returns the JSON and the files.
    ``exact``: the dense record covariance whatever the size (no structured approximation)."""
    from ..build import Staging as _Staging
    from .book import write_book
    from .plots import write_plots

    rec_path = Path(rec_path)
    if not (0.0 < alpha < 1.0):
        raise InputError(f"--alpha must be between 0 and 1, got {alpha!r}")
    if alpha_name is not None and not (0.0 < alpha_name <= alpha):
        raise InputError(f"--alpha-name must be above 0 and at most --alpha ({alpha:g}), got {alpha_name!r}")
    rec = _read(rec_path) if rec is None else rec
    structured = dg.uses_structured(rec, model, False if exact else None)
    try:
        check_diagnose_fits(rec.kind, rec.n, 2 if getattr(rec, "planar", False) else 3,
                            structured=structured)
    except ResourceError as e:
        raise InputError(str(e), file=rec_path) from None
    try:
        backend = get_backend() if structured and rec.kind == "length" else None
        try:
            diag = dg.diagnose(rec, model, alpha, structured=False if exact else None, alpha_name=alpha_name,
                               backend=backend)
        finally:
            if backend is not None:
                backend.close()
    except RecordingsError as e:
        raise InputError(e.message, file=rec_path, where=e.where) from None
    except ModelError as e:
        raise InputError(str(e), file=task_label or rec_path) from None
    result = diag.to_json()
    result = {"name": "diagnosis", "version": __version__,
              "recordings": rec_path.name, "simulation": task_label, **result,
              "warnings": [*warnings, *(f"{rec_path}, {n}" for n in getattr(rec, "notes", ()))]}
    with _Staging(out_dir, force=force) as tmp:
        (tmp / "diagnosis.json").write_text(json.dumps(result, indent=1, ensure_ascii=False, allow_nan=False)
                                            + "\n", encoding="utf-8")
        made = [tmp / "diagnosis.json"]
        if workbook:
            made.append(write_book(diag, tmp / "diagnosis.xlsx", params=model.params, source=rec_path.name))
        if plots:
            made += write_plots(diag, tmp)
    return result, [Path(out_dir) / p.name for p in made]


def cmd_diagnose(args) -> int:
    from ..taskfile import collecting_notes

    with collecting_notes() as notes:
        model, label = load_model(args.task, args.sigma_um)
    result, files = run_diagnose(Path(args.recordings), model, Path(args.out), alpha=args.alpha,
                                 plots=not args.no_plots, workbook=not args.no_workbook, task_label=label,
                                 force=args.force, exact=args.exact, alpha_name=args.alpha_name,
                                 warnings=notes)
    for w in result["warnings"]:
        print(f"cmmwb: warning: {w}", file=sys.stderr)
    print(result["summary"])
    for f in files:
        print(f"  -> {f}")
    return 0


# -- simulate -------------------------------------------------------------------------------------

def parse_effect(text: str, probes) -> tuple[str, object]:
    where = f"--effect {text}"
    if "=" not in text:
        raise InputError("expected NAME=VALUE", where=where)
    name, value = (s.strip() for s in text.split("=", 1))
    if name not in sm.EFFECT_NAMES:
        raise InputError(f"unknown effect {name!r}; choose one of {', '.join(sm.EFFECT_NAMES)}", where=where)

    def numbers(s: str, k: int) -> list[float]:
        parts = [p.strip() for p in s.split(",")]
        if len(parts) != k:
            raise InputError(f"expected {k} number{'s' if k > 1 else ''}, got {s!r}", where=where)
        out = []
        for p in parts:
            try:
                v = float(p)
            except ValueError:
                raise InputError(f"{p!r} is not a number", where=where) from None
            if not math.isfinite(v):
                raise InputError(f"{p!r} is not a finite number", where=where)
            out.append(v)
        return out

    if name == "probe_qualification":
        if ":" not in value:
            raise InputError("expected probe_qualification=PROBE:dx,dy,dz (µm)", where=where)
        pid, vec = value.split(":", 1)
        return name, {pid.strip(): numbers(vec, 3)}
    if name == "offset_drift":
        return name, numbers(value, 3)
    if name == "probe_lobing":
        if ":" not in value:
            raise InputError("expected probe_lobing=PROBE:c2,s2,c3,s3,c4,s4 (µm)", where=where)
        pid, vec = value.split(":", 1)
        return name, {pid.strip(): numbers(vec, 6)}
    if name in sm.STRAIGHTNESS_NAMES:
        return name, numbers(value, 2)       # c2, c3 (µm): orders 2 and 3 of the travel
    if name in sm.PERIODIC_NAMES:
        a, b, period = numbers(value, 3)     # a, b (µm), period (mm)
        if period <= 0:
            raise InputError(f"the period must be above 0 mm, got {period:g}", where=where)
        return name, [a, b, period]
    return name, numbers(value, 1)[0]


def _temperature(text: str | None):
    if text is None:
        return None
    parts = [p.strip() for p in text.split(",")]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise InputError(f"--temperature-C: expected T or T0,T1 in °C, got {text!r}") from None
    if len(vals) not in (1, 2) or not all(math.isfinite(v) for v in vals):
        raise InputError(f"--temperature-C: expected T or T0,T1 in °C, got {text!r}")
    return vals[0] if len(vals) == 1 else tuple(vals)


def cmd_simulate(args) -> int:
    model, label = load_model(args.task, args.sigma_um, default_mpe1=True)
    probes = model.probes
    planted: dict = {}
    for text in args.effect:
        name, value = parse_effect(text, probes)
        if name == "probe_qualification" and name in planted:
            planted[name].update(value)
        else:
            planted[name] = value
    kw = {}
    if args.hours is not None:
        if not (args.hours > 0):
            raise InputError("--hours must be positive")
        kw["hours"] = args.hours
    if args.repeats is not None:
        if args.layout not in ("iso10360", "stepgauge") or args.repeats < 1:
            raise InputError("--repeats: a positive number, for iso10360 and stepgauge")
        kw["repeats"] = args.repeats
    try:
        L = sm.layout(args.layout, probes, **kw)
        rec = sm.simulate(L, model.params, planted, seed=args.seed, temperature_C=_temperature(args.temperature_C))
    except ModelError as e:
        raise InputError(str(e)) from None
    comments = [f"cmmwb {__version__} simulate --layout {args.layout} --seed {args.seed}",
                f"simulation: {label}",
                "planted: " + (", ".join(f"{k}={v}" for k, v in planted.items()) or "nothing")]
    out = Path(args.out)
    write_text(out, write_recordings(rec, comments=comments))
    print(f"{rec.n} {rec.kind} records ({args.layout}), planted "
          + (", ".join(f"{k} = {v}" for k, v in planted.items()) or "nothing") + f" -> {out}")
    return 0


# -- the demonstration ------------------------------------------------------------------------------

DEMO_PROBES = (pc.Probe("P1", (0.0, 0.0, -50.0)),)


def task_toml(params: pc.Parameters, probes, name: str, note: str) -> str:
    lines = [f"# {note}", "[task]", 'kind = "pointcloud"', f'name = "{name}"', "", "[parameters]"]
    for k in pc.Parameters.__dataclass_fields__:
        lines.append(f"{k} = {getattr(params, k)!r}")
    for p in probes:
        lines += ["", "[[probes]]", f'id = "{p.id}"',
                  "offset_mm = [" + ", ".join(repr(float(v)) for v in p.offset_mm) + "]"]
    return "\n".join(lines) + "\n"


def demo(out_dir: Path) -> list[Path]:
    """Two cases into ``out_dir``: a squareness error concealed in an ISO 10360-2 length test
    (no larger in any record than noise reaches anyway, only in the diagonal lengths) found and
    modelled; and a pitch
    error measured with one probe offset, reported as aliased with an x scale error."""
    from ..build import Staging as _Staging

    out_dir = Path(out_dir)
    params = pc.Parameters(**MPE1)
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
    print(f"\n[diagnose] mismatch locator demonstrations -> {out_dir}/")
    for name, planted, seed, note in cases:
        t = time.perf_counter()
        L = sm.iso10360(DEMO_PROBES)
        rec = sm.simulate(L, params, planted, seed=seed, temperature_C=20.0)
        case_dir = out_dir / name
        with _Staging(case_dir) as tmp:
            write_recordings(rec, tmp / "recordings.csv",
                             comments=[f"cmmwb demo: {note}", f"planted: {planted}, seed {seed}"])
            (tmp / "task.toml").write_text(task_toml(params, DEMO_PROBES, f"demo_{name}", note), encoding="utf-8")
        result, made = run_diagnose(case_dir / "recordings.csv", model, case_dir, source="demo",
                                    task_label=str(case_dir / "task.toml"))
        files += [case_dir / "recordings.csv", case_dir / "task.toml", *made]
        print(f"\n  [{name}] {note}  ({time.perf_counter() - t:.1f} s)")
        print(f"    planted: {', '.join(f'{k} = {v}' for k, v in planted.items())}")
        print(f"    {result['summary']}")
        for f in [case_dir / "recordings.csv", case_dir / "task.toml", *made]:
            print(f"    -> {f}")
    return files
