"""``whiskerid posterior``: emcee posteriors of ζ, f_1, κ (EI or C) from recordings."""

import io
import math
import sys
from pathlib import Path

from .._choices import LIKELIHOODS, MOVES, PINS
from ..io import WriteError, atomic_path
from ._added_mass import added_masses
from ._calibrate import DATA_OPTIONS, add_data_options, check_data_options, load_observations
from ._common import (
    QUIET_HELP,
    WATCH,
    HelpFormatter,
    check_outputs,
    interrupts,
    one_line,
    say,
    show_progress,
)


def add_posterior(sub, command_error) -> None:
    """Register the ``posterior`` sub-command."""
    p = sub.add_parser(
        "posterior",
        help="posteriors of zeta, f1, kappa (EI or C) with emcee",
        description=(
            "Sample the posterior of the calibration model (shared kappa and zeta, own "
            "nuisances per recording, unknown noise sigma per recording) with emcee, walkers "
            "started from the calibration's Laplace approximation. Gaussian likelihood with the "
            "linear nuisances marginalised analytically, or Student-t (--likelihood student) "
            "with them sampled. Priors from the record's [prior] table (defaults: zeta uniform "
            "on (0, 0.95), f1_hz log-uniform over a decade either side of the fit, sigma_rel "
            "log-uniform on [1e-6, 10]). Writes DIR/posterior.toml (the record with a "
            "[posterior] table), DIR/chain.h5, DIR/corner.png, DIR/trace.png and "
            "DIR/predictive.png (the data against the 5-95% band of simulated recordings). "
            "The calibration's warnings are repeated, and a posterior 68% half-width "
            "narrower than calibrate's 1-sigma by more than 1.5x is a warning. A run "
            "shorter than 50 autocorrelation times is reported as not converged; --resume "
            "continues it. A record calibrated with --model nonlinear is sampled in the "
            "nonlinear model: f0 and zeta0 (reported as f1_hz and zeta), the nonlinear "
            "coefficients it fitted (flat priors) and the backbone at the smallest and largest "
            "amplitudes, with the linear nuisances sampled (each step solves the slow flow: "
            "slower, give --steps 2000 or more)."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("recordings", nargs="+", type=Path, metavar="REC", help="CSV/NPZ/NPY recordings")
    p.add_argument("--fit", type=Path, required=True, help="record from whiskerid calibrate (TOML)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--walkers", type=int, default=32, help="emcee walkers")
    p.add_argument("--steps", type=int, default=3000, help="steps per walker")
    p.add_argument("--seed", type=int, default=0, help="seed (start and emcee's random state)")
    p.add_argument(
        "--move",
        choices=MOVES,
        default="de",
        help="emcee proposal: de (differential evolution; autocorrelation times about a third "
        "of the stretch move's here), stretch (emcee's default), de-snooker (several modes)",
    )
    p.add_argument(
        "--likelihood",
        choices=LIKELIHOODS,
        default="gaussian",
        help="noise model: gaussian (linear nuisances marginalised) or student (Student-t with "
        "--nu degrees of freedom, nuisances sampled)",
    )
    p.add_argument("--nu", type=float, default=4.0, help="Student-t degrees of freedom")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue DIR/chain.h5 by --steps (the same recordings and settings only; the "
        "summary and plots in DIR are replaced)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace what DIR holds (a chain included) and start afresh; without it or "
        "--resume an existing output is refused; an output that is one of the inputs is "
        "refused even with --force",
    )
    p.add_argument(
        "--chains",
        type=int,
        default=1,
        help="independent ensembles of --walkers each (seeds --seed, --seed + 1, ...); with 2 "
        "or more, ArviZ gives R-hat and bulk/tail ESS of each quantity across them (needs "
        "whiskerid[arviz])",
    )
    p.add_argument(
        "--netcdf",
        type=Path,
        metavar="FILE",
        help="also write the run as ArviZ InferenceData (NetCDF: posterior, sample_stats, "
        "observed_data, posterior_predictive; needs whiskerid[arviz]); an existing FILE is "
        "refused unless --force (or --resume)",
    )
    p.add_argument(
        "--no-plots",
        action="store_true",
        help="skip the corner, trace and posterior-predictive PNGs",
    )
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    # Data options, as in `whiskerid calibrate` (read by its load_observations); those not
    # given are taken from the fit record's [fit.options] table.
    add_data_options(p)
    p.add_argument("--pin", choices=PINS, default="auto", help="auto: the fit's pin")
    p.add_argument("--modes", type=int, help="modes in the model (the fit's by default)")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=lambda args: _cmd_posterior(args, command_error, p))


#: What ``posterior`` writes into its --out folder.
OUTPUTS = ("posterior.toml", "chain.h5", "corner.png", "trace.png", "predictive.png")

#: The nonlinear model's coefficients, printed when a nonlinear record is sampled.
NONLINEAR_REPORTED = ("gamma_per_m2", "quadratic_per_m", "coulomb_m_s2")

#: Samples (all recordings together) above which a note says how to use fewer.
MANY_SAMPLES = 20_000


def _cmd_posterior(args, command_error, parser) -> dict:
    import numpy as np

    from ..fit import read_static_test
    from ..model import load_record
    from ..posterior import sample_posterior

    if args.walkers < 2 or args.steps < 1:
        raise command_error("--walkers must be >= 2 and --steps >= 1")
    if not (np.isfinite(args.nu) and args.nu > 0):
        raise command_error(f"--nu {args.nu!r} must be a positive number")
    if args.resume and args.force:
        raise command_error("--resume continues the chain and --force replaces it: give one")
    if args.chains < 1:
        raise command_error(f"--chains {args.chains} must be >= 1")
    if args.chains > 1 or args.netcdf is not None:
        from ..posterior import import_arviz

        try:
            import_arviz()
        except ImportError as err:
            flag = "--netcdf" if args.netcdf is not None else "--chains"
            raise command_error(f"{flag} needs ArviZ: {one_line(err)}") from None
    chain = args.out / "chain.h5"
    _check_out(args, command_error, chain)
    check_data_options(args)

    record = load_record(args.fit)
    used = fit_options(args, parser, record)
    obs_lists = [load_observations(p, record, args) for p in args.recordings]
    obs = [o for lst in obs_lists for o in lst]
    masses = added_masses(args.added_mass, args.recordings, obs_lists, command_error)
    _note_data_size(obs, record, args)
    static = read_static_test(args.static) if args.static else None
    settings = _settings(args, used)
    if args.resume:
        _check_same_run(chain, settings, command_error)
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.resume:
        chain.unlink(missing_ok=True)  # --force: start afresh
        _store_settings(chain, settings, command_error)
    policy = interrupts()
    WATCH.notes.append(lambda: _chain_note(chain))
    try:
        with policy.deferred():
            post = sample_posterior(
                record,
                obs,
                walkers=args.walkers,
                steps=args.steps,
                seed=args.seed,
                backend=chain,
                resume=args.resume,
                progress=show_progress(args),
                move=args.move,
                static=static,
                added_mass=masses,
                n_modes=args.modes,
                pin=args.pin,
                likelihood=args.likelihood,
                nu=args.nu,
                stop=policy.stop_requested,
                chains=args.chains,
            )
    except OSError as err:
        _drop_empty_chain(chain, args.resume)
        kept = _chain_note(chain) or f"{chain} was not kept"
        why = (
            one_line(err)
            if isinstance(err, WriteError)
            else f"could not write {chain}: {one_line(err)}"
        )
        raise command_error(f"{why}; {kept}") from None
    except BaseException:
        # Refused (bad settings for this record) or stopped before any step: a chain with
        # no samples would only block the corrected run ("already exists").
        _drop_empty_chain(chain, args.resume)
        raise
    WATCH.notes.clear()
    out_toml = post.record.save(args.out / "posterior.toml")
    d = post.diagnostics
    for name in ("f1_hz", "zeta", "kappa", "EI", "C", *NONLINEAR_REPORTED):
        if name in post.params:
            q = post.params[name]
            tau, ess = (f"{q[k]:.3g}" if math.isfinite(q[k]) else "unknown (too few steps)"
                        for k in ("tau", "ess"))  # fmt: skip
            arviz = ""
            if "rhat" in q:
                arviz = (f", R-hat {q['rhat']:.4f}, ESS bulk {q['ess_bulk']:.0f} "
                         f"tail {q['ess_tail']:.0f}")  # fmt: skip
            print(f"{name} = {interval_text(q)}, tau {tau}, ESS {ess}{arviz}", file=sys.stderr)
            if name in post.calibration.get("width_ratio", {}):
                print(f"    {_ratio_text(post.calibration, name)}", file=sys.stderr)
    print(f"acceptance {d['acceptance']:.3f}; {d['message']}", file=sys.stderr)
    if args.chains > 1:
        print(f"{args.chains} chains: largest R-hat {d['max_rhat']:.4f}", file=sys.stderr)
    for warning in post.calibration.get("warnings", []):
        print(f"warning: {warning}", file=sys.stderr)
    out = {**post.to_json(), "out": str(out_toml), "chain": str(chain), "options": used}
    if args.netcdf is not None:
        from ..io import atomic_path

        try:
            with atomic_path(args.netcdf) as tmp:
                post.to_arviz().to_netcdf(str(tmp))
        except OSError as err:
            msg = f"could not write --netcdf {args.netcdf}: {one_line(err)}"
            raise command_error(msg) from None
        out["netcdf"] = str(args.netcdf)
    if not args.no_plots:
        from ..plot import plot_corner, plot_predictive, plot_trace

        out["corner"] = str(plot_corner(args.out / "corner.png", post))
        out["trace"] = str(plot_trace(args.out / "trace.png", post))
        out["predictive"] = str(plot_predictive(args.out / "predictive.png", post))
    print(f"wrote {args.out}", file=sys.stderr)
    return out


def _ratio_text(agreement: dict, name: str) -> str:
    """The posterior's 68% half-width against calibrate's 1-sigma, and against its layers."""
    text = f"68% half-width / calibrate's 1-sigma = {agreement['width_ratio'][name]:.3g}"
    layers = [(agreement.get("width_ratio_sandwich", {}).get(name), "without model error"),
              (agreement.get("width_ratio_white", {}).get(name), "white-noise")]  # fmt: skip
    given = [f"{what} {r:.3g}" for r, what in layers if r is not None]
    return text + (f" (its 1-sigma {', '.join(given)})" if given else "")


def _check_out(args, command_error, chain: Path) -> None:
    """The output policy: refuse outputs over inputs, an existing chain without --resume or
    --force, --resume without a chain, and too little space for the chain."""
    if args.out.exists() and not args.out.is_dir():
        raise command_error(f"--out {args.out} is a file; give a folder")
    if args.resume and not chain.is_file():
        raise command_error(f"--resume: no chain at {chain}; leave --resume out to start one")
    inputs = {"REC": args.recordings, "--fit": args.fit, "--static": args.static}
    names = [n for n in OUTPUTS if not (args.resume and n == "chain.h5")]
    if args.netcdf is not None:
        check_outputs({"--netcdf": args.netcdf}, inputs, force=args.force or args.resume)
    # Per walker and step: the parameters (a few shared, a few per recording; the nonlinear
    # model samples the linear coefficients too), the
    # log-probability and emcee's bookkeeping, as float64; twice over for HDF5's chunks.
    per_step = args.chains * args.walkers * (8 + 8 * len(args.recordings)) * 8 * 2
    for n in names:
        check_outputs(
            {"--out": args.out / n},
            inputs,
            force=args.force or args.resume,
            exists_hint="pass --resume to continue the chain there, or --force to replace it",
            min_free_bytes=per_step * args.steps + (1 << 20),
        )


def fit_options(args, parser, record) -> dict:
    """Fill the data options not given with those the fit used (its ``[fit.options]``).

    Returns:
        The data options in force, as option name → value (those at their default left out).
    """
    stored = record.extra.get("fit", {}).get("options", {})
    used, taken = {}, []
    for dest in DATA_OPTIONS:
        value = getattr(args, dest)
        if value == parser.get_default(dest) and dest in stored:
            value = stored[dest]
            setattr(args, dest, value)
            taken.append(f"--{dest.replace('_', '-')} {value}")
        if value != parser.get_default(dest):
            used[dest] = value
    if taken:
        say(f"data options from the fit record: {', '.join(taken)}")
    return used


def _settings(args, used: dict) -> dict:
    """What a resumed chain must share with the run that started it."""
    from ..fit import sha256_of

    files = [*args.recordings, args.fit] + ([args.static] if args.static else [])
    return {
        "data": [{"name": Path(f).name, "sha256": sha256_of(f)} for f in files],
        "options": {k: used[k] for k in sorted(used)},
        "model": {
            "likelihood": args.likelihood,
            "nu": args.nu,
            "pin": args.pin,
            "modes": args.modes,
            "walkers": args.walkers,
            # only where given: a chain started before --chains existed still resumes
            **({"chains": args.chains} if args.chains > 1 else {}),
        },
    }


_SETTINGS_KEY = "whiskerid_settings"


def _store_settings(chain: Path, settings: dict, command_error) -> None:
    import json

    try:
        import h5py
    except ImportError:
        raise command_error("posterior's chain file needs h5py (pip install h5py)") from None
    image = io.BytesIO()  # HDF5 never writes to the disk itself (run_sampler says why)
    try:
        with h5py.File(image, "w") as f:
            f.attrs[_SETTINGS_KEY] = json.dumps(settings, sort_keys=True)
        with atomic_path(chain) as tmp:
            tmp.write_bytes(image.getvalue())
    except OSError as err:  # a WriteError, naming the chain
        raise command_error(one_line(err)) from None


def _check_same_run(chain: Path, settings: dict, command_error) -> None:
    """Refuse to continue a chain on other data or under other settings."""
    import json

    import h5py

    with h5py.File(chain, "r") as f:
        stored = f.attrs.get(_SETTINGS_KEY)
    if stored is None:
        raise command_error(f"--resume: {chain} does not say which data it was run on; "
                            "start afresh with --force")  # fmt: skip
    old = json.loads(stored)
    for part, what in (("data", "recordings or fit record"), ("options", "data options"),
                       ("model", "model settings")):  # fmt: skip
        if old.get(part) != settings[part]:
            raise command_error(
                f"--resume: {chain} was run with other {what} "
                f"({_diff(old.get(part), settings[part])}); resume with the same ones, or "
                "start afresh with --force or another --out"
            )


def _diff(old, new) -> str:
    if isinstance(old, list) and isinstance(new, list):
        a = [f"{d['name']} {d['sha256'][:8]}" for d in old]
        b = [f"{d['name']} {d['sha256'][:8]}" for d in new]
        return f"then {', '.join(a)}; now {', '.join(b)}"
    keys = sorted(set(old or {}) | set(new))
    return "; ".join(
        f"{k}: then {(old or {}).get(k)}, now {new.get(k)}"
        for k in keys
        if (old or {}).get(k) != new.get(k)
    )


def _chain_steps(chain: Path) -> int | None:
    """Finished steps in a chain file (None: no readable chain)."""
    try:
        import h5py

        with h5py.File(chain, "r") as f:
            return int(f["whiskerid"].attrs["iteration"]) if "whiskerid" in f else 0
    except (OSError, KeyError, ImportError):
        return None


def _drop_empty_chain(chain: Path, resumed: bool) -> None:
    """Remove a chain this run started that holds no step."""
    if not resumed and chain.exists() and not _chain_steps(chain):
        chain.unlink(missing_ok=True)


def _chain_note(chain: Path) -> str | None:
    """What an interrupted run kept: the chain, resumable."""
    steps = _chain_steps(chain)
    if steps is None:
        return None
    if steps == 0:
        return f"no step was finished; {chain} holds no samples"
    return f"kept {chain} with {steps} finished steps: continue it with --resume"


def _note_data_size(obs, record, args) -> None:
    """Say before minutes of sampling how much data each step reads, and how to use less."""
    n = sum(int(o.t.size) for o in obs)
    if n <= MANY_SAMPLES:
        return
    import math

    f1 = float(record.whisker().natural_frequencies_hz[0])
    tau = 1.0 / (2 * math.pi * f1 * max(float(record.zeta), 1e-6))
    end = max(float(o.t[0]) for o in obs) + math.log(100.0) * tau
    hint = (f"the decay falls to 1 % about {math.log(100.0) * tau:.3g} s after its release "
            f"(the fit's f1 and zeta): --t-end {end:.4g} keeps that much")  # fmt: skip
    if args.t_end is not None:
        hint = "a shorter --t-end uses less"
    say(f"note: {n} samples in {len(obs)} recording(s) from the release on; each of the "
        f"{args.walkers * args.steps} log-probability evaluations reads them all, which can "
        f"take minutes; {hint}; or run fewer --steps and --resume later")  # fmt: skip


def interval_text(q: dict) -> str:
    """Median with its 68 % and 95 % intervals, with enough digits that the 68 % bounds differ.

    A narrow posterior far from zero (f_1 = 16.328 Hz known to 1e-4 Hz) printed to five
    significant digits shows the same number three times; the digits follow the interval.
    """
    width = abs(q["q84"] - q["q16"])
    scale = max(abs(q["median"]), abs(q["q16"]), abs(q["q84"]))
    digits = 5
    if width > 0 and scale > 0:
        digits = max(digits, math.ceil(math.log10(scale / width)) + 2)
    f = f".{min(digits, 15)}g"
    return (
        f"{q['median']:{f}} (68%: {q['q16']:{f}} .. {q['q84']:{f}}; "
        f"95%: {q['q2.5']:{f}} .. {q['q97.5']:{f}})"
    )
