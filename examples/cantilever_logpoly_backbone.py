"""Does an identified backbone (polynomials in ln a) whiten the cantilever, make repeats agree?

The parametric nonlinear model bends ``f(a)`` and ``ζ(a)`` by fixed laws (κ, γ, velocity²);
the 30 cm beam's frequency follows none of them. Here each recording of
``examples/calibrate_cantilever.py`` (same record and release detection, thinned to
``--stride``, every repeat of one length cut to the same number of samples so that one
compiled program serves them all) is fitted with

* ``parametric``: the nonlinear model with κ, velocity² and cubic terms;
* ``spline`` (JSON key): ``f(a)``, ``ζ(a)`` as polynomials in ``ln a`` through ``K`` knots
  (``calibrate_nonlinear(..., knots=K)``), ``K`` chosen by the information criterion of
  :func:`whiskerid.fit._nonlinear._select.calibrate_logpoly_backbone`;

at 50 cm both with the free second mode (``free_modes=True``). Per recording it prints the
residual's PSD over the sensor noise's near f1 and near the second mode's line (1 is white),
the lag-1 autocorrelation, ΔBIC of the chosen backbone against the parametric fit (on the
flexible fit's scale: residual variance and HAC ratio; negative favours it), and ``f``
and ``ζ`` with 1σ at a reference amplitude inside every repeat's informed range (the
geometric middle of their overlap: the physically comparable number) and at the smallest
informed amplitude ``a_lo``. Then χ²/dof of the repeats at the reference amplitude. Prints
one JSON object.

    .venv/bin/python examples/cantilever_logpoly_backbone.py [--lengths 30 50] [--knots 2 3 4]
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibrate_cantilever import ROOT
from calibrate_cantilever_nonlinear import noise_ratio, repeats, second_mode_hz, spread

import whiskerid as wi
from whiskerid.fit import calibrate_nonlinear
from whiskerid.fit._nonlinear import backbone_at, calibrate_logpoly_backbone, criterion
from whiskerid.fit._nonlinear._free_modes import _line_near

STRIDE = {30: 16, 50: 32}


def cut(o, n: int):
    """The first ``n`` samples of an observation."""
    return wi.Observation(o.t[:n], o.y[:n], observable=o.observable, name=o.name,
                          source=o.source, selection=o.selection)  # fmt: skip


def row_of(cal, o, lines) -> dict:
    bands = noise_ratio(cal, o, lines)["bands"]
    return {
        "status": cal.status,
        "ratio_f1": bands[0]["ratio"],
        "ratio_f2": bands[1]["ratio"] if len(bands) > 1 else None,
        "lag1": cal.diagnostics["lag1_autocorr"][0],
        "f_lo": [cal.params["f1_hz"]["value"], cal.params["f1_hz"]["std"]],
        "zeta_lo": [cal.params["zeta"]["value"], cal.params["zeta"]["std"]],
        "a_start_m": cal.per_recording[0]["amplitude_start_m"],
    }


def session_minutes(name: str) -> float:
    """Clock time of a recording (minutes) from its file name ``MM-DD_hh-mm-ss_…``."""
    hh, mm, ss = (int(v) for v in name[6:14].split("-"))
    return hh * 60 + mm + ss / 60


def drift_between(out: dict) -> dict:
    """Does a drift in session time explain the repeats' spread at the reference amplitude?
    A straight line in clock time fitted to each model's ``f`` and ``ζ`` there (weighted by
    their 1σ): slope per minute and χ²/dof before and after."""
    rows = out["recordings"]
    m = np.asarray([session_minutes(r["file"]) for r in rows])
    res = {}
    for name in ("parametric", "spline"):
        for key in ("f_hz", "zeta"):
            std_key = "f_std" if key == "f_hz" else "zeta_std"
            v = np.asarray([r[name]["at_reference"][key] for r in rows])
            s = np.asarray([r[name]["at_reference"][std_key] for r in rows])
            A = np.stack([np.ones_like(m), m - m.mean()], axis=1) / s[:, None]
            coef, *_ = np.linalg.lstsq(A, v / s)
            chi2 = float(np.sum((A @ coef - v / s) ** 2))
            res[f"{name}_{key}"] = {"per_minute": float(coef[1]),
                                    "chi2_per_dof_after": chi2 / max(v.size - 2, 1)}  # fmt: skip
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "cantilever")
    ap.add_argument("--lengths", type=int, nargs="+", default=[30, 50])
    ap.add_argument("--knots", type=int, nargs="+", default=[2, 3, 4])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--from-json", type=Path, help="add the drift analysis to a saved summary")
    args = ap.parse_args(argv)
    if args.from_json:
        summary = json.loads(args.from_json.read_text())
        for out in summary.values():
            out["drift_between_recordings"] = drift_between(out)
        print(json.dumps(summary, indent=1))
        return 0
    if not args.data.exists():
        print(f"no data at {args.data}", file=sys.stderr)
        return 2
    summary = {}
    for length in args.lengths:
        record, obs = repeats(args.data, length, STRIDE[length], args.repeats)
        n = min(o.t.size for o in obs)
        obs = [cut(o, n) for o in obs]
        lines = [_line_near(obs, second_mode_hz(record))]
        modes, free = (2, True) if length == 50 else (1, False)
        rows, fits = [], []
        for o in obs:
            lin = wi.calibrate(record, o, n_modes=modes)
            par = calibrate_nonlinear(lin, [o], terms=("kappa", "quadratic", "cubic"),
                                      free_modes=free)  # fmt: skip
            spl = calibrate_logpoly_backbone(lin, [o], knots=args.knots, free_modes=free)
            sel = spl.diagnostics["knot_selection"]
            scale = (sel["scale"]["s2"], sel["scale"]["hac_ratio"], sel["scale"]["n"])
            rows.append({
                "file": o.name,
                "parametric": row_of(par, o, [par.params["f1_hz"]["value"], *lines]),
                "spline": {**row_of(spl, o, [spl.params["f1_hz"]["value"], *lines]),
                           "knots": sel["chosen"], "delta_bic_knots": sel["delta"],
                           "a_lo_m": spl.diagnostics["a_lo_m"]},
                "delta_bic_spline_vs_parametric": criterion(spl, scale) - criterion(par, scale),
            })  # fmt: skip
            fits.append((par, spl))
            print(f"{length} cm {o.name}: K={sel['chosen']} ratio f1 "
                  f"{rows[-1]['spline']['ratio_f1']:.3g} (parametric "
                  f"{rows[-1]['parametric']['ratio_f1']:.3g}), dBIC "
                  f"{rows[-1]['delta_bic_spline_vs_parametric']:.4g}", file=sys.stderr)  # fmt: skip
        # a reference amplitude inside every repeat's informed range
        lo = max(r["spline"]["a_lo_m"] for r in rows)
        hi = min(r["spline"]["a_start_m"] for r in rows)
        a_ref = float(np.sqrt(lo * hi))
        out = {"stride": STRIDE[length], "samples": n, "reference_amplitude_m": a_ref,
               "informed_overlap_m": [lo, hi], "recordings": rows}  # fmt: skip
        for name, i in (("parametric", 0), ("spline", 1)):
            at = [backbone_at(f[i], a_ref) for f in fits]
            for r, b in zip(rows, at, strict=True):
                r[name]["at_reference"] = b
            out[f"{name}_repeats_at_reference"] = {
                "f_hz": spread([b["f_hz"] for b in at], [b["f_std"] for b in at]),
                "zeta": spread([b["zeta"] for b in at], [b["zeta_std"] for b in at]),
            }
        out["drift_between_recordings"] = drift_between(out)
        f0 = [r["parametric"]["f_lo"] for r in rows]
        out["parametric_repeats_f0"] = spread([v for v, _ in f0], [s for _, s in f0])
        summary[f"{length}cm"] = out
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
