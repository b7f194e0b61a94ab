"""``whiskerid calibrate``: fit a whisker's κ (f_1), ζ and EI or C to recordings."""

import argparse
import contextlib
import math
from pathlib import Path

from .._choices import EXCITATIONS, OBSERVABLES, PINS, SOLVERS
from ._added_mass import add_added_mass_option, added_masses
from ._common import FORCE_HELP, HelpFormatter, check_outputs, progress_step


def add_calibrate(sub, command_error) -> None:
    """Register the ``calibrate`` sub-command."""
    p = sub.add_parser(
        "calibrate",
        help="fit stiffness (f1, kappa, EI or C), damping zeta and nuisances to recordings",
        description=(
            "Calibrate a whisker from one or more recordings, fitted jointly: free decay "
            "(pluck or tap), a sine base excitation at --fb (amplitude --hb known or not), a "
            "measured base acceleration (--base-col), and optionally a static test "
            "(--static CSV with force_n, deflection_m). Vibrations alone determine only f1 "
            "(kappa = EI/(rho a)) and zeta: EI or C is derived from the record's geometry "
            "(--pin geometry) or material (--pin material), or from the static test. "
            "Writes the record with fitted values and a [fit] table (values, 1-sigma, "
            "correlations, status, residuals, data files with SHA-256)."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("recordings", nargs="+", type=Path, metavar="REC", help="CSV/NPZ/NPY recordings")
    p.add_argument("--whisker", type=Path, required=True, help="the whisker's record (TOML)")
    p.add_argument("--out", type=Path, required=True, help="calibrated record to write (TOML)")
    add_data_options(p)
    p.add_argument(
        "--pin",
        choices=PINS,
        default="auto",
        help="what fixes EI or C without a static test (auto = geometry)",
    )
    p.add_argument(
        "--modulus-tolerance",
        type=float,
        default=0.2,
        help="--pin material: relative 1-sigma of the record's modulus, carried into rho a's "
        "and C's 1-sigma (0.2: spring wires' spread and the equivalent-beam convention)",
    )
    p.add_argument("--modes", type=int, default=2, help="modes in the model")
    p.add_argument(
        "--f1-start",
        type=float,
        help="centre the start search on this f1 (Hz) instead of the record's (searched within "
        "a factor 2.5 of it)",
    )
    p.add_argument("--zeta-per-mode", action="store_true", help="one zeta per mode")
    p.add_argument(
        "--solver",
        choices=SOLVERS,
        default="levenberg-marquardt",
        help="least-squares solver (Levenberg-Marquardt by variable projection; dogleg and "
        "gauss-newton: optimistix over every parameter)",
    )
    p.add_argument(
        "--model",
        choices=("linear", "nonlinear", "auto"),
        default="linear",
        help="linear (free decays are tested for amplitude-dependent frequency and damping: "
        "'check' when found), nonlinear (mode 1 with cubic stiffness and amplitude-dependent "
        "damping, free decays only: f1 and zeta at small amplitude plus the backbone f(a), "
        "zeta(a)) or auto (nonlinear when the test rejects the linear fit)",
    )
    p.add_argument(
        "--free-modes",
        action="store_true",
        help="with --model nonlinear (or auto): modes 2 and up get their own frequency and "
        "damping, started at the data's line near the beam's f_k, instead of the beam's ratio "
        "to f1. Use it when the beam model puts a higher mode in the wrong place: a "
        "linear or nonlinear fit then leaves a line in the residual spectrum near f2 "
        "('residual_spectrum' in --json). Reports f2_hz, zeta_2 (...) and stores them in "
        "the record, which simulate plays; posterior does not sample such a record. "
        "Free decays only, --modes 2 or more",
    )
    p.add_argument(
        "--fix",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="hold a reported quantity at a value (f1_hz or zeta; repeatable), e.g. "
        "--fix zeta=0.03: its 1-sigma is reported as 0 (linear model only)",
    )
    p.add_argument(
        "--bounds",
        action="append",
        default=[],
        metavar="NAME=LO:HI",
        help="keep a reported quantity inside (LO, HI) (f1_hz or zeta; repeatable), e.g. "
        "--bounds f1_hz=40:50: a value that ends at a bound has its 1-sigma refused (null)",
    )
    p.add_argument(
        "--profile",
        metavar="NAME",
        help="also a profile-likelihood interval of f1_hz or zeta: refit with it fixed on 21 "
        "values within 4 sigma, the interval where delta chi^2 = 1 ('profile' in --json)",
    )
    p.add_argument(
        "--profile-plot",
        type=Path,
        help="with --profile: save delta chi^2 against the value, beside the 1-sigma, as this PNG",
    )
    p.add_argument(
        "--plot",
        type=Path,
        help="save data, fit and residuals as this PNG (with added masses: the decays without "
        "and with the mass, and the frequency shift)",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=lambda args: _cmd_calibrate(args, command_error, p))


#: The options of :func:`add_data_options` that a fit record keeps (``[fit.options]``), so
#: that ``posterior`` reads the recordings as the fit did.
DATA_OPTIONS = (
    *("observable", "time_col", "signal_col", "scale", "units_g", "excitation", "fb", "hb"),
    *("base_col", "sensor_x", "fit_gain", "gain_known", "t_start", "t_end", "added_mass"),
)


def add_data_options(p: argparse.ArgumentParser) -> None:
    """What the recordings hold and which part to use: the options :func:`load_observations`
    reads (shared by ``calibrate`` and ``posterior``)."""
    p.add_argument(
        "--observable",
        choices=("auto", *OBSERVABLES),
        default="auto",
        help="what the signal is; auto: from the column name or the units metadata",
    )
    p.add_argument("--time-col", default="t", help="time column (s)")
    p.add_argument(
        "--signal-col",
        help="signal column (the first non-base column by default); calibrate: two columns "
        "'hall_a,hall_b' fit the two Hall sensors' bending planes each on its own and write "
        "the second one's into the record's [planes] table",
    )
    p.add_argument(
        "--scale", type=float, default=1.0, help="multiply the signal by this (e.g. 9.80665 for g)"
    )
    p.add_argument(
        "--units-g", action="store_true", help="the signal is acceleration in g (scale 9.80665)"
    )
    p.add_argument(
        "--excitation",
        choices=("auto", *EXCITATIONS),
        default="auto",
        help="auto: from the recording's metadata, base if --base-col, else decay",
    )
    p.add_argument("--fb", type=float, help="sine excitation frequency (Hz)")
    p.add_argument("--hb", type=float, help="sine excitation amplitude (m); unknown if absent")
    p.add_argument("--base-col", help="column with the measured base acceleration (m/s^2)")
    p.add_argument("--sensor-x", type=float, help="where the signal is read (m from the clamp)")
    p.add_argument(
        "--fit-gain",
        action="store_true",
        help="fit the sensor gain (always fitted, as gain*amplitude, for voltage/adc "
        "unless --gain-known)",
    )
    p.add_argument("--gain-known", action="store_true", help="take the Hall gain from the record")
    p.add_argument("--static", type=Path, help="static test CSV: force_n, deflection_m[, x_m]")
    p.add_argument(
        "--t-start",
        type=float,
        help="use samples from this time (s); decay: the release is detected by default",
    )
    p.add_argument("--t-end", type=float, help="use samples up to this time (s)")
    add_added_mass_option(p)


def check_data_options(args) -> None:
    """Refuse NaN, infinities and impossible values in the numbers of :func:`add_data_options`.

    Raises:
        ValueError: Which option is wrong and what it must be.
    """
    import numpy as np

    for flag, value in (("--sensor-x", args.sensor_x), ("--t-start", args.t_start),
                        ("--t-end", args.t_end)):  # fmt: skip
        if value is not None and not np.isfinite(value):
            raise ValueError(f"{flag} {value!r} must be a finite number")
    if not np.isfinite(args.scale) or args.scale == 0:
        raise ValueError(f"--scale {args.scale!r} must be a finite, non-zero number")
    for flag, value in (("--fb", args.fb), ("--hb", args.hb)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise ValueError(f"{flag} {value!r} must be a positive number")
    if None not in (args.t_start, args.t_end) and args.t_end <= args.t_start:
        raise ValueError(f"--t-end {args.t_end:g} must be later than --t-start {args.t_start:g}")


def load_observations(path: Path, record, args) -> list:
    """Read one recording and turn it into :class:`whiskerid.fit.Observation` s per the
    flags: one per free decay found in a pluck recording (several plucks are fitted
    jointly), else one."""
    from ..fit import observations_from_file

    return observations_from_file(
        path,
        record,
        time_col=args.time_col,
        signal_col=args.signal_col,
        base_col=args.base_col,
        observable=args.observable,
        excitation=args.excitation,
        scale=args.scale,
        units_g=args.units_g,
        fb_hz=args.fb,
        hb_m=args.hb,
        sensor_x_m=args.sensor_x,
        fit_gain=args.fit_gain,
        gain_known=args.gain_known,
        t_start=args.t_start,
        t_end=args.t_end,
    )


def _check_profile(args, parameters, command_error) -> None:
    """Refuse a ``--profile`` (and ``--profile-plot``) that cannot be drawn."""
    from ..fit import LIMITABLE

    if args.profile_plot is not None and args.profile is None:
        raise command_error(f"--profile-plot {args.profile_plot}: give --profile NAME too")
    if args.profile is None:
        return
    if args.profile not in LIMITABLE:
        raise command_error(f"--profile {args.profile!r}: give one of {', '.join(LIMITABLE)}")
    if parameters is not None or args.model != "linear" or args.added_mass:
        raise command_error(
            f"--profile {args.profile}: profiles the plain linear fit; leave out --fix, "
            "--bounds, --model and --added-mass"
        )


def parse_limits(fix: list[str], bounds: list[str], command_error):
    """``--fix NAME=VALUE`` and ``--bounds NAME=LO:HI`` as a :class:`whiskerid.fit.Parameters`
    (None when neither is given); a malformed one is refused naming the flag and value."""
    from ..fit import CalibrationError, Parameters

    if not fix and not bounds:
        return None
    out = Parameters()
    seen: set[str] = set()
    try:
        for flag, items in (("--fix", fix), ("--bounds", bounds)):
            for item in items:
                name, sep, value = item.partition("=")
                name = name.strip()
                if not sep or not name or not value:
                    shape = "NAME=VALUE" if flag == "--fix" else "NAME=LO:HI"
                    raise command_error(
                        f"{flag} {item!r}: give {shape}, e.g. "
                        + ("zeta=0.03" if flag == "--fix" else "f1_hz=40:50")
                    )
                if name in seen:
                    raise command_error(f"{flag} {item!r}: {name} is fixed or bounded twice")
                seen.add(name)
                if flag == "--fix":
                    out = out.fix(name, value)
                    continue
                lo, colon, hi = value.partition(":")
                if not colon:
                    raise command_error(f"--bounds {item!r}: give NAME=LO:HI, e.g. f1_hz=40:50")
                out = out.bound(name, lo, hi)
    except CalibrationError as e:
        raise command_error(str(e)) from None
    return out


def _cmd_calibrate(args, command_error, parser) -> dict:
    import sys

    from ..fit import calibrate, read_static_test
    from ..io import atomic_path
    from ..model import load_record

    inputs = {"REC": args.recordings, "--whisker": args.whisker, "--static": args.static}
    outputs = {"--out": args.out, "--plot": args.plot, "--profile-plot": args.profile_plot}
    check_outputs(outputs, inputs, force=args.force)
    check_data_options(args)
    if not (math.isfinite(args.modulus_tolerance) and 0 <= args.modulus_tolerance < 1):
        raise command_error(
            f"--modulus-tolerance {args.modulus_tolerance!r} must be a relative 1-sigma in "
            "[0, 1), e.g. 0.05 for 5 %"
        )
    if args.f1_start is not None and not (
        math.isfinite(args.f1_start) and 0.01 <= args.f1_start <= 1e4
    ):
        raise command_error(f"--f1-start {args.f1_start:g}: give a frequency from 0.01 to 10000 Hz")
    if args.free_modes:
        _check_free_modes(args, command_error)
    parameters = parse_limits(args.fix, args.bounds, command_error)
    _check_profile(args, parameters, command_error)
    if parameters is not None and (args.model != "linear" or args.added_mass):
        raise command_error(
            "--fix/--bounds apply to the linear fit of one whisker: leave out --model and "
            "--added-mass"
        )
    record = load_record(args.whisker)
    columns = _plane_columns(args.signal_col, command_error)
    if columns is not None and parameters is not None:
        raise command_error("--fix/--bounds: give one --signal-col, not two planes")
    if columns is not None:
        return _calibrate_planes(args, parser, record, columns, command_error)
    progress_step("reading the recordings, finding the releases")
    obs_lists = [load_observations(p, record, args) for p in args.recordings]
    obs = [o for lst in obs_lists for o in lst]
    masses = added_masses(args.added_mass, args.recordings, obs_lists, command_error)
    if masses is not None:
        _check_added_mass(args, command_error)
    static = read_static_test(args.static) if args.static else None
    progress_step("fitting (a new recording shape is compiled once: tens of seconds)")
    cal = calibrate(
        record,
        obs,
        static=static,
        n_modes=args.modes,
        zeta_per_mode=args.zeta_per_mode,
        pin=args.pin,
        solver=args.solver,
        f1_start_hz=args.f1_start,
        added_mass=masses,
        modulus_tolerance=args.modulus_tolerance,
        model=args.model,
        free_modes=args.free_modes,
        parameters=parameters,
    )
    profile = None
    if args.profile:
        from ..fit import profile_interval

        progress_step(f"profiling {args.profile} (21 refits)")
        profile = profile_interval(
            record, obs, args.profile, static=static, n_modes=args.modes,
            zeta_per_mode=args.zeta_per_mode, pin=args.pin, solver=args.solver,
            f1_start_hz=args.f1_start, modulus_tolerance=args.modulus_tolerance,
        )  # fmt: skip
    progress_step("writing")
    # All or nothing: the figure is rendered to a temporary file next to --plot before the
    # record is written, and put in place only after it, so a full disk while plotting
    # leaves neither (it used to leave --out written and the command refused).
    with contextlib.ExitStack() as stack:
        if args.plot:
            from ..plot import plot_added_mass, plot_calibration

            plot_tmp = stack.enter_context(atomic_path(args.plot))
            (plot_calibration if masses is None else plot_added_mass)(plot_tmp, cal)
        _with_options(cal.record, args, parser).save(args.out)
    print(cal.report(), file=sys.stderr)
    print(f"wrote {args.out}", file=sys.stderr)
    out = {**cal.to_json(), "out": str(args.out)}
    if profile is not None:
        out["profile"] = profile
        print(
            f"profile of {profile['name']}: Δχ² = 1 at {profile['lower']} and "
            f"{profile['upper']} (1σ ±{profile['std']:.3g} around {profile['value']:.6g})",
            file=sys.stderr,
        )
        if args.profile_plot:
            from ..plot import plot_profile

            plot_profile(args.profile_plot, profile)
            out["profile_plot"] = str(args.profile_plot)
            print(f"wrote {args.profile_plot}", file=sys.stderr)
    if args.plot:
        out["plot"] = str(args.plot)
        print(f"wrote {args.plot}", file=sys.stderr)
    if cal.status != "ok":
        print(
            f"status {cal.status}: see the warnings above; the record holds the status and them",
            file=sys.stderr,
        )
    return out


def _check_free_modes(args, command_error) -> None:
    """Refuse ``--free-modes`` where the fit has no nonlinear higher mode to free."""
    if args.model == "linear":
        raise command_error(
            "--free-modes frees the nonlinear fit's higher modes: add --model nonlinear "
            "(or auto), or leave --free-modes out"
        )
    if args.modes < 2:
        raise command_error(
            f"--free-modes frees modes 2 and up, but --modes is {args.modes}: "
            "give --modes 2 or more"
        )
    if args.static or args.base_col or args.added_mass or args.excitation not in ("auto", "decay"):
        raise command_error(
            "--free-modes fits free decays only (no --static, --base-col, --added-mass or "
            "sine/base excitation): leave it out for these recordings"
        )
    if args.signal_col and "," in args.signal_col:
        raise command_error("--free-modes fits one plane: give one --signal-col")


def _check_added_mass(args, command_error) -> None:
    """Refuse what the added-mass method does not combine with."""
    if args.static:
        raise command_error("--static and added masses both fix EI: give one of them")
    if args.pin != "auto":
        raise command_error(
            f"--pin {args.pin}: with added masses the plucks determine EI and C; leave --pin out"
        )


def _with_options(record, args, parser):
    """The fit record with the data options given in its ``[fit.options]`` table."""
    options = {d: getattr(args, d) for d in DATA_OPTIONS
               if getattr(args, d) != parser.get_default(d)}  # fmt: skip
    fit = record.extra.get("fit")
    if fit is None or not options:
        return record
    return record.replace(extra={**record.extra, "fit": {**fit, "options": options}})


def _plane_columns(signal_col: str | None, command_error) -> tuple[str, str] | None:
    """The two columns of ``--signal-col A,B`` (two Hall sensors), or None for one."""
    if signal_col is None or "," not in signal_col:
        return None
    cols = tuple(c.strip() for c in signal_col.split(","))
    if len(cols) != 2 or not all(cols) or cols[0] == cols[1]:
        raise command_error(
            f"--signal-col {signal_col!r}: give one column, or two distinct ones (the vertical "
            "plane's sensor first, e.g. hall_a,hall_b)"
        )
    return cols


def _calibrate_planes(args, parser, record, columns, command_error) -> dict:
    """Both bending planes: each sensor's recordings fitted on their own (plane A from the
    record, plane B from the record's lateral plane); the record written is plane A's fit
    (its top-level values: f1 and zeta of the vertical plane) with the lateral plane's
    frequency ratio and zeta in its ``[planes]`` table and plane B's fit in ``[fit.lateral]``."""
    import sys
    from argparse import Namespace

    import numpy as np

    from ..fit import calibrate
    from ..terrain import SensorPlanes, plane_records

    if args.added_mass:
        raise command_error("--added-mass calibrates one plane: give one --signal-col at a time")
    if args.static:
        raise command_error(
            "--static fixes EI of one plane: calibrate the two planes without it, "
            "or one column at a time"
        )
    try:
        planes = SensorPlanes.from_record(record)
    except ValueError as err:
        raise command_error(f"{args.whisker}: {err}") from None
    starts = plane_records(record)
    cals = []
    for col, start in zip(columns, starts, strict=True):
        one = Namespace(**{**vars(args), "signal_col": col})
        obs = [o for p in args.recordings for o in load_observations(p, start, one)]
        cal = calibrate(
            start,
            obs,
            n_modes=args.modes,
            zeta_per_mode=args.zeta_per_mode,
            pin=args.pin,
            solver=args.solver,
            f1_start_hz=args.f1_start,
        )
        print(f"--- plane of {col}", file=sys.stderr)
        print(cal.report(), file=sys.stderr)
        cals.append(cal)
    a, b = (c.record.whisker() for c in cals)
    ratio = float(np.sqrt(float(b.EI) / float(a.EI)))
    zeta_b = cals[1].record.zeta
    table = {
        **planes.to_table(),
        "lateral_frequency_ratio": ratio,
        "lateral_zeta": list(zeta_b) if isinstance(zeta_b, tuple) else float(zeta_b),
    }
    SensorPlanes.from_record(record.replace(extra={"planes": table}))  # range checks
    first = _with_options(
        cals[0].record, Namespace(**{**vars(args), "signal_col": columns[0]}), parser
    )
    extra = dict(first.extra)
    if "fit" in extra:
        extra["fit"] = {
            **extra["fit"],
            "lateral": {**cals[1].record.extra.get("fit", {}), "signal_col": columns[1]},
        }
    first.replace(extra={**extra, "planes": table}).save(args.out)
    print(
        f"wrote {args.out} (plane of {columns[0]} at the top level, {columns[1]} in [planes])",
        file=sys.stderr,
    )
    out = {
        **cals[0].to_json(),
        "out": str(args.out),
        "planes": {
            col: {
                "f1_hz": float(w.natural_frequencies_hz[0]),
                "zeta": float(np.ravel(c.record.zeta)[0]),
                "status": c.status,
                "params": c.to_json()["params"],
            }
            for col, c, w in zip(columns, cals, (a, b), strict=True)
        },
        "lateral_frequency_ratio": ratio,
    }
    for col, c in zip(columns, cals, strict=True):
        if c.status != "ok":
            print(f"plane of {col}: status {c.status}: see the warnings above", file=sys.stderr)
    return out
