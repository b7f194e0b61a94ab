"""``whiskerid fleet calibrate|check``: calibrate many whiskers session after session, and
flag the sessions in which a whisker has changed."""

import hashlib
import sys
from pathlib import Path

from .._choices import OBSERVABLES, PINS, SOLVERS
from ._common import (
    FORCE_HELP,
    QUIET_HELP,
    WATCH,
    CommandError,
    HelpFormatter,
    check_outputs,
    say,
)

_LAYOUT = (
    "ROOT/<whisker-id>/<session>/<recordings>.csv|.npy|.npz, one folder per whisker and per "
    "session (sessions are taken in the order of their names: name them so that they sort in "
    "time, e.g. 2026-11-25), each whisker's record in ROOT/<whisker-id>/whisker.toml (or one "
    "shared record with --whisker)"
)
_RULE = (
    "Each whisker's history is searched for a lasting change: its sessions are read in "
    "order, each against the reference of the usable sessions before it that were not found "
    "changed (the first --baseline K only form it). A session's change from the reference "
    "mean has z = change / sqrt(sigma_day^2/K_ref + max(sigma_day^2, s^2/n)), s being the "
    "spread of its own n plucks and sigma_day the largest of: the reference sessions' "
    "scatter, the same scatter pooled over the fleet's whiskers, the spread of repeated "
    "plucks within them (over the square root of the plucks per session) and the median "
    "1-sigma of the reference fits. A step is found where |z| >= --z, a drift where a "
    "two-sided CUSUM of the z's (allowance 0.5) reaches --drift; either only when the "
    "session's change is at least --min-change-f1 / --min-change-zeta percent. The change "
    "is then located by a two-segment search over the whole history: the session where it "
    "began and every later one are flagged, with its size and 1-sigma. A later session "
    "whose fit failed (or whose row is torn or not a number) is flagged as 'fit'. Sessions "
    "of a driving health log (FLEET/health.csv, 'fleet drive') form histories of their own."
)


def add_parser(sub) -> None:
    """Register the ``fleet`` command and its two sub-commands."""
    p = sub.add_parser(
        "fleet",
        help="calibrate a fleet of whiskers session after session, and flag changed whiskers",
        description=(
            "Whisker health across a fleet. 'fleet calibrate' fits every session of every "
            "whisker (skipping what is done), 'fleet drive' adds a whisker's f1 and zeta "
            "identified from driving recordings (no pluck) to a health log, 'fleet check' "
            "flags the sessions in which a whisker's f1 or zeta has changed. "
            f"Layout: {_LAYOUT}."
        ),
        formatter_class=HelpFormatter,
    )
    fsub = p.add_subparsers(dest="fleet_command", required=True, metavar="SUBCOMMAND")
    _add_calibrate(fsub)
    _add_drive(fsub)
    _add_check(fsub)
    _add_simulate(fsub)


def _add_calibrate(fsub) -> None:
    p = fsub.add_parser(
        "calibrate",
        help="fit every new session into one record each and the table FLEET/fleet.csv",
        description=(
            "Calibrate every session of every whisker: each pluck on its own (their spread "
            "is what 'fleet check' judges changes by) and all plucks of a session jointly "
            "(the session's f1, zeta, 1-sigma and record FLEET/<whisker>/<session>.toml, as "
            "'whiskerid calibrate --out' writes it). Each pluck is cut to the longest power of "
            "two samples it holds (the decay's start kept, at most half of its tail dropped), "
            "so that plucks of one length are fitted by one compiled program whatever the "
            "whisker; windows under 64 samples or 5 periods of f1 are left out. The table "
            "FLEET/fleet.csv "
            "holds per session: f1, zeta and their 1-sigma, the uncertainty's kind, status, "
            "failed checks, the single plucks' values and spread, the files' SHA-256 and when "
            "it was fitted. A session already in the table with the same data, record and "
            "settings is skipped, so a nightly run fits only what is new; a bad recording "
            "gets its own status and the others go on. The table is rewritten atomically as "
            f"sessions finish: an interrupted run keeps what it finished. Layout: {_LAYOUT}."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("root", type=Path, metavar="ROOT", help="the fleet's recordings")
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="FLEET",
        help="output folder (records and fleet.csv); may hold an earlier run's",
    )
    p.add_argument("--whisker", type=Path,
                   help="one record (TOML) for every whisker, instead of each whisker's "
                   "ROOT/<whisker-id>/whisker.toml")  # fmt: skip
    p.add_argument(
        "--observable",
        choices=("auto", *OBSERVABLES),
        default="auto",
        help="what the signal is; auto: from the column name or the units metadata",
    )
    p.add_argument("--time-col", default="t", help="time column (s)")
    p.add_argument("--signal-col", help="signal column (the first one by default)")
    p.add_argument("--scale", type=float, default=1.0, help="multiply the signal by this")
    p.add_argument("--units-g", action="store_true", help="the signal is acceleration in g")
    p.add_argument("--modes", type=int, default=2, help="modes in the model")
    p.add_argument("--pin", choices=PINS, default="auto",
                   help="what fixes EI or C (auto = geometry)")  # fmt: skip
    p.add_argument("--solver", choices=SOLVERS, default="levenberg-marquardt",
                   help="least-squares solver (optimistix)")  # fmt: skip
    p.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="spread the sessions over a Ray cluster: 'auto' (the cluster this machine is in), "
        "'local' (a private one on this machine, --workers CPUs) or an address; the numbers "
        'are the same as without (needs pip install "whiskerid[fleet]"; the recordings '
        "must be at the same path on every machine)",
    )
    p.add_argument("--workers", type=int, help="CPUs of a --ray local cluster (all by default)")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=_cmd_calibrate)


def _add_check(fsub) -> None:
    p = fsub.add_parser(
        "check",
        help="flag the sessions in which a whisker's f1 or zeta changed beyond its repeats",
        description=(
            _RULE + " Writes OUT/flags.csv (the flagged whisker-sessions: parameter, value, "
            "reference, change in percent, z, p-value, CUSUM, the session where the change "
            "began) and OUT/<whisker>.png for each flagged whisker (f1 and zeta over "
            "sessions, the reference and its band, where the change began), and prints the "
            "changes found."
        ),
        formatter_class=HelpFormatter,
    )  # fmt: skip
    p.add_argument("fleet", type=Path, metavar="FLEET", help="a 'fleet calibrate' output folder")
    p.add_argument("--out", type=Path, help="folder for flags.csv and the PNGs (FLEET/check)")
    p.add_argument("--baseline", type=int, default=2,
                   help="usable sessions forming each whisker's first reference (K)")  # fmt: skip
    p.add_argument("--z", type=float, default=4.0,
                   help="|z| at and above which one session's change is a step")  # fmt: skip
    p.add_argument("--drift", type=float, default=5.0,
                   help="CUSUM of z at and above which a slow change is a drift")  # fmt: skip
    p.add_argument("--min-change-f1", type=float, default=1.0,
                   help="smallest relative change of f1 flagged (percent)")  # fmt: skip
    p.add_argument("--min-change-zeta", type=float, default=20.0,
                   help="smallest relative change of zeta flagged (percent)")  # fmt: skip
    p.add_argument("--no-plots", action="store_true", help="write no PNGs")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=_cmd_check)


def _add_drive(fsub) -> None:
    p = fsub.add_parser(
        "drive",
        help="a whisker's f1 and zeta from driving recordings (no pluck), into FLEET/health.csv",
        description=(
            "Output-only identification of a whisker's f1 and zeta from recordings made while "
            "driving: each recording (cut into blocks of --block seconds) gives a Welch "
            "spectrum; narrow lines (the motor, periodic textures) are masked; each block's "
            "log-spectrum over 0.8-1.25 f1 (wider, +-6 zeta f1, for a broad peak) is fitted by "
            "the resonance of the base-motion "
            "model times the base's spectrum: a smooth part (a quadratic in ln f), the ripple "
            "of the rear axle's echo of the front's profile (its delay from the cepstrum) "
            "and a contact patch's null (its place searched), with a Cauchy loss; "
            "the drive's values are the medians of the blocks', their 1-sigma from the "
            "blocks' spread. The drive is written as one session of FLEET/health.csv (the "
            "columns of fleet.csv, the blocks in the place of the plucks), which 'fleet "
            "check' reads as a history of its own beside the pluck sessions."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("fleet", type=Path, metavar="FLEET", help="the fleet's output folder")
    p.add_argument("recordings", type=Path, nargs="+", metavar="RECORDING",
                   help="driving recordings (.csv, .npz, .npy) of one whisker")  # fmt: skip
    p.add_argument("--whisker-id", required=True, help="the whisker's id (its folder's name)")
    p.add_argument("--session", required=True,
                   help="the drive's session name (sorts in time, e.g. 2026-11-25)")  # fmt: skip
    p.add_argument("--whisker", type=Path, required=True,
                   help="the whisker's record (TOML): f1 and zeta to start from")  # fmt: skip
    p.add_argument("--signal-col", help="signal column (the first one by default)")
    p.add_argument("--time-col", default="t", help="time column (s)")
    p.add_argument("--block", type=float, default=60.0,
                   help="longest block (s, 20-86400); a drive needs at least 4 blocks (240 s "
                   "of driving with 60 s blocks)")  # fmt: skip
    p.add_argument("--force", action="store_true",
                   help="replace the session's row if the health log has it")  # fmt: skip
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=_cmd_drive)


# --------------------------------------------------------------------------- drive
def _cmd_drive(args) -> dict:
    import numpy as np

    from ..io import RecordingError, read_recording

    if not (args.block >= 20 and args.block <= 86400):
        raise CommandError(f"--block {args.block} must be 20 s (two 10 s windows) to 86400 s")
    for name, value in (("--whisker-id", args.whisker_id), ("--session", args.session)):
        if not value.strip() or "/" in value or value.startswith((".", "_")):
            raise CommandError(f"{name} {value!r} must be a plain name (no '/', no leading "
                               "'.' or '_')")  # fmt: skip
    signals, rates, seen = [], [], {}
    for path in args.recordings:
        try:
            rec = read_recording(path, time_col=args.time_col)
            y = rec.signal(args.signal_col)
        except (RecordingError, KeyError, ValueError) as err:
            raise CommandError(" ".join(str(err).split())) from None
        dt = np.diff(rec.t)
        if rec.t.size < 2 or not np.all(dt > 0):
            raise CommandError(f"{path}: its time column does not increase")
        y = np.asarray(y, dtype=float)
        _check_drive_signal(path, y)
        digest = hashlib.sha256(y.tobytes()).hexdigest()
        if digest in seen:
            raise CommandError(f"{path} holds the same samples as {seen[digest]}: give each "
                               "recording once")  # fmt: skip
        seen[digest] = path
        rates.append(1.0 / float(np.median(dt)))
        signals.append((path.name, y))
    rate = float(np.median(rates))
    if max(abs(r / rate - 1) for r in rates) > 0.05:
        raise CommandError("the recordings' sample rates differ by more than 5 % "
                           f"({min(rates):.4g}-{max(rates):.4g} Hz); give one rate's")  # fmt: skip
    from ..fleet import MIN_BLOCKS, driving_blocks

    lengths = [y.size / rate for _, y in signals]
    if driving_blocks(lengths, rate, args.block) < MIN_BLOCKS:
        raise CommandError(
            f"too short: {sum(lengths):.0f} s of driving in {len(lengths)} recording(s) give "
            f"{driving_blocks(lengths, rate, args.block)} block(s) of --block "
            f"{args.block:g} s; fleet drive needs at least {MIN_BLOCKS} blocks, "
            f"{MIN_BLOCKS * args.block:g} s of driving (each recording at least 20 s)"
        )
    from ..fleet import (
        HEALTH_NAME,
        FleetError,
        drive_problem,
        health_row,
        identify_driving,
        read_table,
    )
    from ..fleet import write_table as write_log
    from ..model import RecordError, load_record

    try:
        record = load_record(args.whisker)
    except (RecordError, OSError) as err:
        raise CommandError(" ".join(str(err).split())) from None
    log = args.fleet / HEALTH_NAME
    try:
        rows = read_table(log)
    except FleetError as err:
        raise CommandError(str(err)) from None
    key = (args.whisker_id, args.session)
    if any((r["whisker"], r["session"]) == key for r in rows) and not args.force:
        raise CommandError(f"{log} already holds {args.whisker_id}/{args.session}; pass "
                           "--force to replace it, or give another --session")  # fmt: skip
    f1 = float(record.whisker().natural_frequencies_hz[0])
    zeta = float(np.atleast_1d(record.zeta)[0])
    try:
        fit = identify_driving(signals, rate, f1, zeta, block_s=args.block)
    except ValueError as err:
        raise CommandError(str(err)) from None
    row = health_row(args.whisker_id, args.session, fit, [p.name for p in args.recordings])
    rows = [r for r in rows if (r["whisker"], r["session"]) != key] + [row]
    write_log(log, rows)
    if not args.quiet:
        used = sum(b["status"] == "ok" for b in fit.blocks)
        say(f"{args.whisker_id}/{args.session}: {fit.status}: f1 {fit.f1_hz:.4g} ± "
            f"{fit.f1_std:.2g} Hz, zeta {fit.zeta:.3g} ± {fit.zeta_std:.2g} from {used} of "
            f"{len(fit.blocks)} block(s), {fit.seconds:.0f} s of driving; wrote {log}")  # fmt: skip
        if fit.status != "ok":
            say(f"  not ok: {drive_problem(fit)}; the drive is logged with status "
                f"'{fit.status}' ('fleet check' flags it as 'fit')")  # fmt: skip
    return {"log": str(log), "status": fit.status, "f1_hz": fit.f1_hz, "f1_std": fit.f1_std,
            "zeta": fit.zeta, "zeta_std": fit.zeta_std, "f1_dof": fit.f1_dof,
            "zeta_dof": fit.zeta_dof, "seconds": fit.seconds, "blocks": fit.blocks,
            "problem": "" if fit.status == "ok" else drive_problem(fit)}  # fmt: skip


#: A recording with more than this fraction of its samples at its largest or smallest value
#: is clipped (the converter's rail) or stuck: its spectrum is not the whisker's.
RAIL_FRACTION = 0.02


def _check_drive_signal(path, y) -> None:
    """Refuse a driving recording that cannot hold a whisker's response: samples that are
    not numbers, a constant signal, or one that sits on a rail."""
    import numpy as np

    bad = int(np.sum(~np.isfinite(y)))
    if bad:
        raise CommandError(f"{path}: {bad} sample(s) are not finite (NaN or inf); clean or "
                           "drop the recording")  # fmt: skip
    if y.size and np.ptp(y) == 0:
        raise CommandError(f"{path}: the signal is constant ({y[0]:.6g}): a disconnected or "
                           "stuck sensor, no driving response")  # fmt: skip
    for what, value in (("largest", y.max()), ("smallest", y.min())):
        share = float(np.mean(y == value))
        if y.size >= 100 and share > RAIL_FRACTION:
            raise CommandError(
                f"{path}: {100 * share:.1f} % of the samples sit at its {what} value "
                f"{value:.6g} (a rail or a stuck converter); the spectrum of a clipped signal "
                "is not the whisker's"
            )


# --------------------------------------------------------------------------- calibrate
def _cmd_calibrate(args) -> dict:
    if args.modes < 1 or args.modes > 10:
        raise CommandError(f"--modes {args.modes} must be between 1 and 10")
    if args.workers is not None and args.workers < 1:
        raise CommandError(f"--workers {args.workers} must be at least 1")
    if args.workers is not None and args.ray != "local":
        raise CommandError("--workers sets the size of a --ray local cluster; add --ray local")
    if not args.root.is_dir():
        raise CommandError(f"ROOT {args.root} is not a folder; give the fleet's recordings")
    check_outputs({"--out": args.out}, {"ROOT": args.root, "--whisker": args.whisker},
                  force=True, folders=("--out",))  # fmt: skip
    from ..fleet import FleetError, FleetSettings, calibrate_fleet, ray_runner

    settings = FleetSettings(
        n_modes=args.modes, pin=args.pin, solver=args.solver, observable=args.observable,
        time_col=args.time_col, signal_col=args.signal_col, scale=args.scale,
        units_g=args.units_g,
    )  # fmt: skip
    runner = None
    if args.ray:
        if args.ray != "local" and not args.quiet:
            where = "of this machine" if args.ray == "auto" else f"at {args.ray}"
            say(f"joining the Ray cluster {where} (--ray {args.ray}) …")
        try:
            runner = ray_runner(args.ray, num_cpus=args.workers)
        except (FleetError, RuntimeError) as err:
            raise CommandError(str(err)) from None
    table = args.out / "fleet.csv"
    WATCH.notes.append(lambda: f"what finished is kept in {table}" if table.exists() else None)
    run = calibrate_fleet(args.root, args.out, record=args.whisker, settings=settings,
                          runner=runner, progress=not args.quiet)  # fmt: skip
    say(
        f"{run.sessions} session(s): {run.fitted} fitted ({run.failed} not ok), "
        f"{run.skipped} already done; wrote {run.table}"
    )
    for row in run.rows:
        if row["status"] not in ("ok", "check"):
            say(f"  {row['whisker']}/{row['session']}: {row['status']}: {row['checks']}")
    return {
        "table": str(run.table),
        "sessions": run.sessions,
        "fitted": run.fitted,
        "skipped": run.skipped,
        "failed": run.failed,
        "elapsed_s": round(run.elapsed_s, 3),
        "ray": args.ray,
    }


# --------------------------------------------------------------------------- check
def _cmd_check(args) -> dict:
    from ..fleet import HEALTH_NAME, TABLE_NAME

    table = args.fleet / TABLE_NAME
    if not table.is_file() and not (args.fleet / HEALTH_NAME).is_file():
        raise CommandError(f"{args.fleet} holds no {TABLE_NAME} (nor {HEALTH_NAME}); run "
                           "'whiskerid fleet calibrate' (or 'fleet drive') first, or give its "
                           "--out folder")  # fmt: skip
    if args.baseline < 1:
        raise CommandError(f"--baseline {args.baseline} must be at least 1")
    for flag, v in (("--z", args.z), ("--drift", args.drift),
                    ("--min-change-f1", args.min_change_f1),
                    ("--min-change-zeta", args.min_change_zeta)):  # fmt: skip
        if not (v >= 0 and v < float("inf")) or (flag in ("--z", "--drift") and v == 0):
            raise CommandError(f"{flag} {v!r} must be a positive number")
    out = args.out or args.fleet / "check"
    check_outputs({"--out": out}, {"FLEET table": table, "FLEET health log": args.fleet /
                  HEALTH_NAME}, force=True, folders=("--out",))  # fmt: skip
    from ..fleet import FleetError, check_fleet, read_table, refuse_corrupt_values

    rows = []
    for path, source in ((table, None), (args.fleet / HEALTH_NAME, "drive")):
        try:
            got = read_table(path)
            refuse_corrupt_values(path, got)
        except FleetError as err:
            raise CommandError(str(err)) from None
        except UnicodeDecodeError as err:
            raise CommandError(
                f"{path}: byte {err.start} is not UTF-8 text; the table was edited or "
                "damaged: restore it or fit it again"
            ) from None
        if source is None:  # a health log may hold several drives of one session
            _refuse_duplicate_sessions(path, got)
        rows += got if source is None else [{**r, "source": source} for r in got]
    result = check_fleet(
        rows,
        baseline=args.baseline,
        z_min=args.z,
        drift_h=args.drift,
        min_change={"f1_hz": args.min_change_f1 / 100, "zeta": args.min_change_zeta / 100},
    )
    flags_path = _write_flags(out / "flags.csv", result.flags)
    plots = []
    if not args.no_plots:
        from ..plot import plot_fleet_history

        for name, h in sorted(result.histories.items()):
            if not h.flagged:
                continue
            plots.append(str(plot_fleet_history(
                out / f"{name.replace(' (', '-').rstrip(')')}.png", name, h.sessions, h.values,
                h.errors, h.plucks, baseline=h.baseline, centre=h.centre, band=h.band,
                flagged=_flagged_per_parameter(name, h, result.flags), began=h.began,
            )))  # fmt: skip
    _print_flags(result, quiet=args.quiet)
    return {
        "flags": result.flags,
        "events": result.events,
        "changes": result.changes,
        "notes": result.notes,
        "settings": result.settings,
        "flags_csv": str(flags_path),
        "plots": plots,
        "whiskers": len(result.histories),
        "flagged_whiskers": len({f["whisker"] for f in result.flags}),
    }


def _refuse_duplicate_sessions(path: Path, rows: list[dict]) -> None:
    """One row per whisker and session (a joint fit of its plucks): two rows of one session
    would be read as a change between them."""
    seen: dict[tuple, int] = {}
    for line, row in enumerate(rows, start=2):
        key = (row.get("whisker"), row.get("session"))
        if key in seen:
            raise CommandError(
                f"{path}: lines {seen[key]} and {line} are both whisker {key[0]}, session "
                f"{key[1]}; keep one row per session (or fit the session again)"
            )
        seen[key] = line


def _flagged_per_parameter(name: str, history, flags: list[dict]) -> dict[str, list[str]]:
    """Per parameter of ``history``, the sessions flagged for it (a failed fit, ``fit``,
    counts for every one): the figure marks a change on the parameter that changed."""
    mine = [f for f in flags if f["whisker"] == name.split(" (")[0]
            and f["session"] in history.flagged]  # fmt: skip
    return {p: sorted({f["session"] for f in mine if f["parameter"] in (p, "fit")})
            for p in history.values}  # fmt: skip


_FLAG_COLUMNS = ("whisker", "source", "session", "parameter", "value", "baseline",
                 "change_pct", "sigma", "z", "p_value", "cusum", "began", "status")  # fmt: skip


def _write_flags(path: Path, flags: list[dict]) -> Path:
    import csv
    import io

    from ..io import atomic_write

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(_FLAG_COLUMNS)
    for f in flags:
        w.writerow([f"{f[c]:.6g}" if isinstance(f[c], float) else f[c] for c in _FLAG_COLUMNS])
    return atomic_write(path, buf.getvalue())


def _print_flags(result, *, quiet: bool = False) -> None:
    if quiet:
        return
    for note in result.notes:
        say(f"note: {note}")
    names = {"f1_hz": "f1", "zeta": "zeta"}
    for e in result.events:
        where = "" if e["source"] == "pluck" else f" ({e['source']})"
        say(f"{e['whisker']}{where}: {names[e['parameter']]} changed {e['size_pct']:+.2f} % "
            f"± {100 * e['size_sigma'] / abs(e['before']):.2f} % (1 sigma) from session "
            f"{e['began']} on ({e['n_after']} session(s); a {e['rule']} found at "
            f"{e['detected']})")  # fmt: skip
    fits = [f for f in result.flags if f["parameter"] == "fit"]
    for f in fits:
        say(f"{f['whisker']}/{f['session']}: no usable fit ({f['status']})")
    if not result.flags:
        say(f"no change flagged in {len(result.histories)} whisker history(ies)")
        return
    whiskers = len({f["whisker"] for f in result.flags})
    print(f"{len(result.flags)} flag(s) on {whiskers} whisker(s)", file=sys.stderr)


def _add_simulate(fsub) -> None:
    p = fsub.add_parser(
        "simulate",
        help="write a simulated fleet (plucks per whisker and session) to try the others on",
        description=(
            "Write a simulated fleet in the layout 'fleet calibrate' reads: ROOT/whisker-NNN/"
            "whisker.toml and ROOT/whisker-NNN/session-NN/pluck-N.csv (ADS1115 codes at "
            "--rate), each whisker's material and damping off its record's and varying a "
            "little from session to session; --damaged of them change lastingly (zeta x 1.5 "
            "or f1 x 0.97, alternately) from a random session after the first --baseline. "
            "--truth writes what was simulated (CSV: whisker, session, f1_hz, zeta, damaged)."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("root", type=Path, metavar="ROOT", help="folder to write (new or empty)")
    p.add_argument("--whiskers", type=int, default=3, help="number of whiskers")
    p.add_argument("--sessions", type=int, default=4, help="sessions per whisker")
    p.add_argument("--plucks", type=int, default=2, help="plucks per session")
    p.add_argument("--damaged", type=int, default=1, help="whiskers that change")
    p.add_argument("--baseline", type=int, default=2, help="sessions before any change")
    p.add_argument("--rate", type=float, default=860.0, help="sampling rate (Hz)")
    p.add_argument("--seed", type=int, default=0, help="seed of everything drawn")
    p.add_argument("--truth", type=Path, help="also write the truth to this CSV file")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=_cmd_simulate)


def _cmd_simulate(args) -> dict:
    """Write the fleet and its truth; returns the JSON summary."""
    import math

    counts = {"--whiskers": (args.whiskers, 1, 100), "--sessions": (args.sessions, 1, 100),
              "--plucks": (args.plucks, 1, 20), "--damaged": (args.damaged, 0, args.whiskers),
              "--baseline": (args.baseline, 1, args.sessions)}  # fmt: skip
    for flag, (v, lo, hi) in counts.items():
        if not lo <= v <= hi:
            raise CommandError(f"{flag} {v}: give a whole number from {lo} to {hi}")
    if not (math.isfinite(args.rate) and 100 <= args.rate <= 860):
        raise CommandError(f"--rate {args.rate:g}: give a rate from 100 to 860 Hz (the ADS1115)")
    check_outputs({"ROOT": args.root, "--truth": args.truth}, {}, force=args.force,
                  folders=("ROOT",))  # fmt: skip
    from ..fleet import simulate_fleet
    from ..io import atomic_write

    truth = simulate_fleet(args.root, whiskers=args.whiskers, sessions=args.sessions,
                           plucks=args.plucks, damaged=args.damaged, baseline=args.baseline,
                           rate_hz=args.rate, seed=args.seed)  # fmt: skip
    if args.truth:
        lines = ["whisker,session,f1_hz,zeta,damaged"] + [
            f"{r['whisker']},{r['session']},{r['f1_hz']:.6g},{r['zeta']:.6g},{int(r['damaged'])}"
            for r in truth.sessions
        ]
        atomic_write(args.truth, "\n".join(lines) + "\n")
    say(
        f"wrote {args.root}: {args.whiskers} whiskers x {args.sessions} sessions x "
        f"{args.plucks} plucks" + (f"; the truth to {args.truth}" if args.truth else "")
    )
    return {"root": str(args.root), "truth": str(args.truth) if args.truth else None,
            "damage": {w: list(d) for w, d in truth.damage.items()}}  # fmt: skip
