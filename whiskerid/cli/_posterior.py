"""``whiskerid posterior``: emcee posteriors of ζ, f_1, κ (EI or C) from recordings."""

import math
import sys
from pathlib import Path

from .._choices import LIKELIHOODS, MOVES, PINS
from ._calibrate import add_data_options, check_data_options, load_observations
from ._common import HelpFormatter


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
            "[posterior] table), DIR/chain.h5, DIR/corner.png and DIR/trace.png. A run "
            "shorter than 50 autocorrelation times is reported as not converged; --resume "
            "continues it."
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
    p.add_argument("--resume", action="store_true", help="continue DIR/chain.h5 by --steps")
    p.add_argument("--no-plots", action="store_true", help="skip the corner and trace PNGs")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    # Data options, as in `whiskerid calibrate` (read by its load_observations).
    add_data_options(p)
    p.add_argument("--pin", choices=PINS, default="auto", help="auto: the fit's pin")
    p.add_argument("--modes", type=int, help="modes in the model (the fit's by default)")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=lambda args: _cmd_posterior(args, command_error))


def _cmd_posterior(args, command_error) -> dict:
    import numpy as np

    from ..fit import read_static_test
    from ..model import load_record
    from ..posterior import sample_posterior

    if args.out.exists() and not args.out.is_dir():
        raise command_error(f"--out {args.out} is a file; give a folder")
    if args.walkers < 2 or args.steps < 1:
        raise command_error("--walkers must be >= 2 and --steps >= 1")
    if not (np.isfinite(args.nu) and args.nu > 0):
        raise command_error(f"--nu {args.nu!r} must be a positive number")
    check_data_options(args)
    _check_inputs_survive(args, command_error)

    record = load_record(args.fit)
    obs = [o for p in args.recordings for o in load_observations(p, record, args)]
    static = read_static_test(args.static) if args.static else None
    args.out.mkdir(parents=True, exist_ok=True)
    chain = args.out / "chain.h5"
    if args.resume and not chain.exists():
        raise command_error(f"--resume: no chain at {chain}")
    post = sample_posterior(
        record,
        obs,
        walkers=args.walkers,
        steps=args.steps,
        seed=args.seed,
        backend=chain,
        resume=args.resume,
        progress=not (args.quiet or args.json),
        move=args.move,
        static=static,
        n_modes=args.modes,
        pin=args.pin,
        likelihood=args.likelihood,
        nu=args.nu,
    )
    out_toml = post.record.save(args.out / "posterior.toml")
    d = post.diagnostics
    for name in ("f1_hz", "zeta", "kappa", "EI", "C"):
        if name in post.params:
            q = post.params[name]
            print(f"{name} = {interval_text(q)}, tau {q['tau']:.3g}, ESS {q['ess']:.4g}",
                  file=sys.stderr)  # fmt: skip
    print(f"acceptance {d['acceptance']:.3f}; {d['message']}", file=sys.stderr)
    out = {**post.to_json(), "out": str(out_toml), "chain": str(chain)}
    if not args.no_plots:
        from ..plot import plot_corner, plot_trace

        out["corner"] = str(plot_corner(args.out / "corner.png", post))
        out["trace"] = str(plot_trace(args.out / "trace.png", post))
    print(f"wrote {args.out}", file=sys.stderr)
    return out


#: What ``posterior`` writes into its --out folder.
OUTPUTS = ("posterior.toml", "chain.h5", "corner.png", "trace.png")


def _check_inputs_survive(args, command_error) -> None:
    """Refuse inputs that are among the files written into --out (they would be replaced)."""
    from ..io import same_file

    inputs = [*args.recordings, args.fit, args.static]
    for name in OUTPUTS:
        for p in inputs:
            if p is not None and same_file(args.out / name, p):
                raise command_error(
                    f"input {p} would be overwritten by the output {args.out / name}; "
                    "give another --out folder"
                )


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
