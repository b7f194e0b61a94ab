"""The real aluminium cantilever with the nonlinear model: f₀, ζ₀ and the backbone f(a), ζ(a).

Along one decay the beam's frequency rises and its damping falls as the amplitude dies out,
so a linear fit averages them, leaves residuals at f₁ and disagrees with its own repeats.
Here every recording of ``examples/calibrate_cantilever.py`` (same record, same release
detection) is fitted with ``model="linear"`` and ``model="nonlinear"``; for each the JSON
gives status, values with 1σ, the residuals' lag-1 autocorrelation and their spectrum near
f₁ (the share of the residual variance within ±1 Hz of f₁, and the strongest line), the
backbone at the largest and smallest amplitude, and the short-window damped-sine fits
(frequency and damping against amplitude) binned beside the backbone. ``residual_to_noise``
is the fair whiteness measure: the residual's power spectral density within ±12.5 % of f1 and
of the second bending mode's line, over the sensor noise's density there (from the residual's
spectrum beside the band: these recordings ring to their end and have no quiet stretch); 1 is
white. For the lengths in ``--two-modes`` (default 50 cm, whose second mode at 39 Hz holds most
of a one-mode fit's residual) a third fit adds a free second mode (its f2 and ζ2 fitted,
started at the data's line; the beam model puts it 0.8 Hz off). Then all repeats of one length
are fitted jointly and the record saved as ``fits/cantilever-aluminium-<L>cm-nonlinear.toml``,
with a plot.

    .venv/bin/python examples/calibrate_cantilever_nonlinear.py [--lengths 30 50] [--stride 4]
        [--terms kappa quadratic cubic | auto] [--two-modes 50] [--json-out r.json]
        [--figure f.png]
"""

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import itertools

from calibrate_cantilever import ROOT, beam_record, observation

import whiskerid as wi
from whiskerid.fit import calibrate_nonlinear
from whiskerid.fit._checks._spectral_floor import spectral_whiteness
from whiskerid.fit._nonlinear._free_modes import _line_near
from whiskerid.model._nonlinear import COEFFICIENTS


def near_f1_share(o, model_y, f1_hz: float) -> float:
    """Share of the residual variance within ±1 Hz of f1 (uniformly resampled)."""
    r = o.y - model_y
    dt = float(np.median(np.diff(o.t)))
    ru = np.interp(o.t[0] + dt * np.arange(o.t.size), o.t, r)
    p = np.abs(np.fft.rfft(ru - ru.mean())) ** 2
    f = np.fft.rfftfreq(ru.size, dt)
    return float(p[np.abs(f - f1_hz) <= 1.0].sum() / max(p.sum(), 1e-300))


def residual_spectrum(
    o,
    model_y,
    bands=((0.0, 5.0), (5.0, 14.0), (14.0, 19.0), (19.0, 40.0), (40.0, 100.0), (100.0, 1e9)),
) -> dict:
    """The residual's variance share per frequency band (Hz; uniformly resampled) and its
    three strongest lines: where the misfit lives."""
    r = o.y - model_y
    dt = float(np.median(np.diff(o.t)))
    ru = np.interp(o.t[0] + dt * np.arange(o.t.size), o.t, r)
    p = np.abs(np.fft.rfft((ru - ru.mean()) * np.hanning(ru.size))) ** 2
    f = np.fft.rfftfreq(ru.size, dt)
    top = np.argsort(p)[::-1]
    lines = []
    for i in top:
        if all(abs(f[i] - g) > 0.5 for g, _ in lines):
            lines.append((float(f[i]), float(p[i] / p.sum())))
        if len(lines) == 3:
            break
    return {
        "band_share": {f"{lo:g}-{hi:g} Hz": float(p[(f >= lo) & (f < hi)].sum() / p.sum())
                       for lo, hi in bands},
        "lines_hz_share": lines,
    }  # fmt: skip


def noise_ratio(cal, o, lines_hz) -> dict:
    """The residual's PSD against the sensor noise's near f1 and near the second mode's
    line (:func:`whiskerid.fit._checks._spectral_floor.spectral_whiteness`): ratio 1 is white."""
    s = spectral_whiteness(o.t, o.y - cal.curves[0][2], lines_hz, quiet=o.quiet)
    return {"reference": s["reference"], "white": s["white"],
            "bands": [{k: b[k] for k in ("f_hz", "ratio", "ratio_std", "p_value", "white")}
                      for b in s["bands"]]}  # fmt: skip


def summary_of(cal, o, lines_hz=()) -> dict:
    p = cal.params
    out = {
        "status": cal.status,
        "checks": sorted(cal.checks),
        "f1_hz": [p["f1_hz"]["value"], p["f1_hz"]["std"]],
        "zeta": [p["zeta"]["value"], p["zeta"]["std"]],
        "lag1_autocorr": cal.diagnostics["lag1_autocorr"][0],
        "residual_peak_hz_ratio": cal.per_recording[0].get("residual_peak"),
        "residual_share_near_f1": near_f1_share(o, cal.curves[0][2], p["f1_hz"]["value"]),
        "rms_residual_m_s2": cal.diagnostics["rms_residual"][0],
        "residual_to_noise": noise_ratio(cal, o, [p["f1_hz"]["value"], *lines_hz]),
    }
    for k in ("f2_hz", "zeta_2"):
        if k in p:
            out[k] = [p[k]["value"], p[k]["std"]]
    test = cal.diagnostics.get("amplitude_test")
    if test:
        out["amplitude_test_p"] = [test["nonlinear"]["p_value"], test["split"]["p_value"]]
        out["amplitude_message"] = test["message"]
    if hasattr(cal, "backbone"):
        b = cal.backbone
        for k in COEFFICIENTS:
            if k in p:
                out[k] = [p[k]["value"], p[k]["std"]]
        out["backbone"] = b
        out["residual_spectrum"] = residual_spectrum(o, cal.curves[0][2])
        out["backbone_ends"] = {
            "amplitude_m": [b["amplitude_m"][0], b["amplitude_m"][-1]],
            "f_hz": [b["f_hz"][0], b["f_hz"][-1]],
            "zeta": [b["zeta"][0], b["zeta"][-1]],
        }
        out["windows_vs_backbone"] = binned_windows(b)
    return out


def second_mode_hz(record) -> float:
    """The record's beam model's second natural frequency (Hz)."""
    return float(record.replace(n_modes=2).whisker().natural_frequencies_hz[1])


def binned_windows(b: dict, bins: int = 5) -> list[dict]:
    """Short-window f and ζ (medians per amplitude bin) next to the backbone there."""
    a = np.asarray(b["windows"]["amplitude_m"])
    if a.size < bins:
        return []
    edges = np.quantile(a, np.linspace(0, 1, bins + 1))
    out = []
    for lo, hi in itertools.pairwise(edges):
        sel = (a >= lo) & (a <= hi)
        am = float(np.exp(np.mean(np.log(a[sel]))))
        fb = float(np.interp(np.log(am), np.log(b["amplitude_m"]), b["f_hz"]))
        zb = float(np.interp(np.log(am), np.log(b["amplitude_m"]), b["zeta"]))
        out.append({
            "amplitude_m": am,
            "windows_f_hz": float(np.median(np.asarray(b["windows"]["f_hz"])[sel])),
            "backbone_f_hz": fb,
            "windows_zeta": float(np.median(np.asarray(b["windows"]["zeta"])[sel])),
            "backbone_zeta": zb,
        })  # fmt: skip
    return out


def thin(o, stride: int):
    """Every ``stride``-th sample of an observation."""
    if stride <= 1:
        return o
    return wi.Observation(o.t[::stride], o.y[::stride], observable=o.observable, name=o.name,
                          source=o.source, selection=o.selection)  # fmt: skip


def repeats(data: Path, length_cm: int, stride: int, count: int | None = None):
    """The beam's record and its recordings at ``length_cm`` (every ``stride``-th sample; the
    first ``count`` files in name order, all when None)."""
    paths = sorted((data / f"{length_cm}cm").glob("*.npy"))[:count]
    return beam_record(length_cm), [thin(observation(p), stride) for p in paths]


def spread(values, stds) -> dict:
    v, s = np.asarray(values), np.asarray(stds)
    mean = float(np.average(v, weights=1 / s**2))
    return {
        "values": v.tolist(),
        "stds": s.tolist(),
        "weighted_mean": mean,
        "chi2_per_dof": float(np.sum(((v - mean) / s) ** 2) / max(v.size - 1, 1)),
        "max_abs_z": float(np.max(np.abs(v - mean) / s)),
    }


def draw_backbones(summary: dict, path: Path) -> None:
    """f(a) and ζ(a) per beam length: every recording's fitted backbone (lines) over its
    short-window damped-sine fits (points), amplitude as mode 1's tip deflection."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lengths = list(summary)
    fig, axes = plt.subplots(2, len(lengths), figsize=(5.2 * len(lengths), 6.4), squeeze=False)
    for j, length in enumerate(lengths):
        for i, row in enumerate(summary[length]["recordings"]):
            fit = row.get("nonlinear_2_modes", row["nonlinear"])  # the fuller model if fitted
            b = fit.get("backbone")
            if not b:
                continue
            color = f"C{i}"
            w = b["windows"]
            for ax, key, wkey in ((axes[0, j], "f_hz", "f_hz"), (axes[1, j], "zeta", "zeta")):
                ax.plot(np.asarray(w["amplitude_m"]) * 1e3, w[wkey], ".", ms=3, color=color,
                        alpha=0.5)  # fmt: skip
                ax.plot(np.asarray(b["amplitude_m"]) * 1e3, b[key], "-", color=color,
                        label=row["file"][:14] if key == "f_hz" else None)  # fmt: skip
        terms = ", ".join(summary[length].get("terms", []))
        if "nonlinear_2_modes" in summary[length]["recordings"][0]:
            terms += "; free 2nd mode"
        axes[0, j].set_title(f"{length}: fit ({terms}), points: windows", fontsize=9)
        axes[1, j].set_xlabel("mode 1 tip amplitude a (mm)")
        axes[0, j].set_ylabel("f(a) (Hz)")
        axes[1, j].set_ylabel("zeta(a)")
        for ax in axes[:, j]:
            ax.set_xscale("log")
            ax.grid(alpha=0.3)
        axes[0, j].legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "cantilever")
    ap.add_argument("--out", type=Path, default=Path("calibrate-cantilever"))
    ap.add_argument("--fits", type=Path, default=ROOT / "fits")
    ap.add_argument("--lengths", type=int, nargs="+", default=[30, 50])
    ap.add_argument("--no-joint", action="store_true", help="skip the joint fits")
    ap.add_argument(
        "--terms",
        nargs="+",
        default=["kappa", "quadratic", "cubic"],
        help="nonlinear terms (or 'auto': chosen by BIC, several fits each)",
    )
    ap.add_argument("--two-modes", type=int, nargs="*", default=[50],
                    help="lengths (cm) also fitted with a free second mode (f2, zeta2 "
                         "fitted, started at the data's line)")  # fmt: skip
    ap.add_argument("--json-out", type=Path, help="also write the summary here")
    ap.add_argument("--figure", type=Path, help="draw f(a), zeta(a) against short windows here")
    ap.add_argument(
        "--from-json",
        type=Path,
        help="draw --figure from a summary written by --json-out (no fits)",
    )
    ap.add_argument("--stride", type=int, default=1,
                    help="keep every STRIDE-th sample (the beam rings at 6-16 Hz, sampled at "
                         "about 4 kHz: a stride of 4 still gives 60 samples a period)")  # fmt: skip
    args = ap.parse_args(argv)
    terms = "auto" if args.terms == ["auto"] else tuple(args.terms)
    if args.from_json:
        summary = {}
        for f in args.from_json.glob("*.json") if args.from_json.is_dir() else [args.from_json]:
            summary.update(json.loads(f.read_text()))
        draw_backbones(dict(sorted(summary.items())), args.figure)
        return 0
    if not args.data.exists():
        print(f"no data at {args.data}", file=sys.stderr)
        return 2
    summary = {}
    for length_cm in args.lengths:
        record, obs = repeats(args.data, length_cm, args.stride)
        rows = []
        # the second bending mode's line in the data (the beam puts it 2-5 % off)
        f2_line = _line_near(obs, second_mode_hz(record))
        for o in obs:
            lin = wi.calibrate(record, o, n_modes=1)
            nl = wi.calibrate(record, o, n_modes=1, model="nonlinear", nl_terms=terms)
            rows.append({"file": o.name, "linear": summary_of(lin, o, [f2_line]),
                         "nonlinear": summary_of(nl, o, [f2_line])})  # fmt: skip
            if length_cm in args.two_modes:
                lin2 = wi.calibrate(record, o, n_modes=2)
                nl2 = calibrate_nonlinear(lin2, [o], terms=terms, free_modes=True)
                rows[-1]["nonlinear_2_modes"] = summary_of(nl2, o, [f2_line])
                print(f"  two free modes: {nl2.status} f0 {rows[-1]['nonlinear_2_modes']['f1_hz']}"
                      f" zeta0 {rows[-1]['nonlinear_2_modes']['zeta']} f2 "
                      f"{rows[-1]['nonlinear_2_modes'].get('f2_hz')}", file=sys.stderr)  # fmt: skip
            print(f"{length_cm} cm {o.name}: linear {lin.status} zeta {rows[-1]['linear']['zeta']}"
                  f" | nonlinear {nl.status} f0 {rows[-1]['nonlinear']['f1_hz']} zeta0 "
                  f"{rows[-1]['nonlinear']['zeta']}", file=sys.stderr)  # fmt: skip
        out = {"recordings": rows, "terms": list(terms) if terms != "auto" else ["auto"]}
        for model in ("linear", "nonlinear", "nonlinear_2_modes"):
            if model not in rows[0]:
                continue
            out[f"{model}_repeats"] = {
                "f1_hz": spread([r[model]["f1_hz"][0] for r in rows],
                                [r[model]["f1_hz"][1] for r in rows]),
                "zeta": spread([r[model]["zeta"][0] for r in rows],
                               [r[model]["zeta"][1] for r in rows]),
            }  # fmt: skip
        if not args.no_joint:
            joint = wi.calibrate(record, obs, n_modes=1, model="nonlinear", nl_terms=terms)
            for f in joint.record.extra["fit"]["data_files"]:
                f["path"] = os.path.relpath(f["path"], ROOT)
            name = f"{record.name}-nonlinear"
            joint.record.save(args.fits / f"{name}.toml")
            from whiskerid.plot import plot_calibration

            plot_calibration(args.out / f"{name}.png", joint)
            jp = joint.params
            out["joint"] = {
                "status": joint.status,
                "checks": sorted(joint.checks),
                "params": {k: [v["value"], v["std"]] for k, v in jp.items()},
                "backbone": {k: v for k, v in joint.backbone.items() if k != "windows"},
                "lag1_autocorr": joint.diagnostics["lag1_autocorr"],
            }
        summary[f"{length_cm}cm"] = out
    if args.figure:
        draw_backbones(summary, args.figure)
    if args.json_out:
        args.json_out.write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
