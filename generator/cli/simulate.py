"""``cmmwb simulate --layout iso10360 --task TASK.toml --effect squareness_xy=4 --seed 1 --out
rec.csv``: recordings of a realistic layout measured by a CMM drawn from the task's model (Forbes
2025 Table 3 MPE1 without ``--task``), with the planted effects of docs/recordings.md section 4."""

from __future__ import annotations

import inspect
import math
from pathlib import Path

from cmmwb.xlfuncs import validation_sets as vsm
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.recordings import write_recordings

from .. import __version__
from ..errors import InputError, model_errors_named
from ..workbook.atomic import write_text
from .common import add_command


def register(sub) -> None:
    s = add_command(sub, "simulate", "write recordings of a realistic layout with planted effects",
                    "Recordings measured by a CMM drawn from the task's Forbes 2025 model (or Table 3 "
                    "MPE1 without --task), with planted effects named as in docs/recordings.md section 4.",
                    ("cmmwb simulate --layout iso10360 --out rec.csv",
                     "cmmwb simulate --layout stepgauge --effect squareness_xy=4.1 --seed 7 --out rec.csv",
                     "cmmwb simulate --layout ballplate --effect thermal_expansion=1.5 "
                     "--temperature-C 20,23 --out rec.csv",
                     "cmmwb simulate --validation ballplate,stepgauge --effect squareness_xy=20 --out valset"))
    s.add_argument("--layout", choices=sm.LAYOUTS,
                   help="what is measured: " + ", ".join(sm.LAYOUTS) + " (or --validation)")
    s.add_argument("--validation", metavar="WORKPIECE[,WORKPIECE]",
                   help="instead of --layout: a validation set of calibrated workpieces (" + ", ".join(vsm.WORKPIECES)
                        + ") into the folder --out: the tasks, results.csv for cmmwb validate and truth.json "
                          "(docs/validate.md)")
    s.add_argument("--runs", type=int, default=2, help="--validation: measurement runs of every workpiece (default: 2)")
    s.add_argument("--force", action="store_true",
                   help="--validation: replace files in --out edited since cmmwb wrote them, keeping a backup")
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
                   help="length of the session in hours, over which the records' time_s is spread (every "
                        f"layout writes time_s; default: the layout's own, {_default_hours()})")
    s.add_argument("--repeats", type=int, default=None,
                   help="repetitions (iso10360, stepgauge; default: the layout's own)")
    s.add_argument("--out", required=True, metavar="REC.csv", help="recordings CSV to write")
    s.set_defaults(func=run)


def _default_hours() -> str:
    """Each layout's default session length (the ``hours`` of its builder), for the help text."""
    hours = {name: inspect.signature(getattr(sm, name)).parameters["hours"].default for name in sm.LAYOUTS}
    return ", ".join(f"{name} {h:g} h" for name, h in hours.items())


def run(args) -> int:
    from ..diagnosis.run import load_model, planted_text  # the locator (scipy): only when run

    if (args.layout is None) == (args.validation is None):
        raise InputError("give one of --layout (recordings) or --validation (a validation set)")
    model, label = load_model(args.task, args.sigma_um, default_mpe1=True)
    probes = model.probes
    planted: dict = {}
    for text in args.effect:
        name, value = parse_effect(text, probes)
        if name == "probe_qualification" and name in planted:
            planted[name].update(value)
        else:
            planted[name] = value
    if args.validation is not None:
        return _validation_set(args, model, label, planted)
    kw = {}
    if args.hours is not None:
        if not (args.hours > 0):
            raise InputError("--hours must be positive")
        kw["hours"] = args.hours
    if args.repeats is not None:
        if args.layout not in ("iso10360", "stepgauge") or args.repeats < 1:
            raise InputError("--repeats: a positive number, for iso10360 and stepgauge")
        kw["repeats"] = args.repeats
    with model_errors_named():
        L = sm.layout(args.layout, probes, **kw)
        rec = sm.simulate(L, model.params, planted, seed=args.seed, temperature_C=_temperature(args.temperature_C))
    comments = [f"cmmwb {__version__} simulate --layout {args.layout} --seed {args.seed}",
                f"simulation: {label}",
                "planted: " + (", ".join(f"{k}={v}" for k, v in planted.items()) or "nothing")]
    out = Path(args.out)
    write_text(out, write_recordings(rec, comments=comments))
    print(f"{rec.n} {rec.kind} records ({args.layout}), planted {planted_text(planted)} -> {out}")
    return 0


def _validation_set(args, model, label: str, planted: dict) -> int:
    """``--validation``: the workpieces measured by the task's machine into the folder --out."""
    from ..validation.sets import write_set

    names = [w.strip() for w in args.validation.split(",") if w.strip()]
    for w in names:
        if w not in vsm.WORKPIECES:
            raise InputError(f"unknown workpiece {w!r}; choose from {', '.join(vsm.WORKPIECES)}", where="--validation")
    if not names:
        raise InputError("name at least one workpiece", where="--validation")
    if args.runs < 1:
        raise InputError("--runs must be at least 1")
    if args.temperature_C is not None or args.hours is not None or args.repeats is not None:
        raise InputError("--temperature-C, --hours and --repeats belong to --layout")
    probes = model.probes if model.probes_given else vsm.DEFAULT_PROBES
    if not model.probes_given:
        label += f"; probes {', '.join(f'{p.id} {p.offset_mm}' for p in probes)}"
    with model_errors_named(where="--validation"):
        vs, meas, files = write_set(Path(args.out), names, model.params, probes, planted, args.seed, args.runs,
                                    label, force=args.force)
    print(f"{len(vs.labels)} characteristics x {args.runs} runs ({', '.join(names)}), planted "
          + (", ".join(f"{k} = {v}" for k, v in planted.items()) or "nothing") + ":")
    for f in files:
        print(f"  -> {f}")
    return 0


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
        pid, vec = value.rsplit(":", 1)      # a probe id may hold ":" (the numbers do not)
        return name, {pid.strip(): numbers(vec, 3)}
    if name == "offset_drift":
        return name, numbers(value, 3)
    if name == "probe_lobing":
        if ":" not in value:
            raise InputError("expected probe_lobing=PROBE:c2,s2,c3,s3,c4,s4 (µm)", where=where)
        pid, vec = value.rsplit(":", 1)      # a probe id may hold ":" (the numbers do not)
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
