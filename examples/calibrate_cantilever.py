"""Calibrate the real aluminium cantilever (free decay after a pluck, non-uniform timestamps).

Data: ``../shared/data/cantilever`` (see its README): a 50 × 2 mm aluminium beam, E = 70 GPa,
2700 kg/m³, 30 cm or 50 cm long, an ADXL357 accelerometer (5 g, treated as a tip mass)
about 6 cm from the free end, acceleration in g, timestamps at about 4 kHz with gaps.

For every recording the fit starts after the detected release and fits f_1 (κ) and ζ; EI
follows from κ and ρa = ρ b h (the geometry pin). All repeats of one length are then
fitted jointly (shared κ, ζ; own amplitudes, offsets and drifts) and the result is saved
as ``fits/cantilever-aluminium-<L>cm.toml``. Prints one JSON object; saves plots.

    .venv/bin/python examples/calibrate_cantilever.py [--data DIR] [--out DIR] [--fits DIR]
"""

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

import whiskerid as wi
from whiskerid.fit import G0, release_time

ROOT = Path(__file__).resolve().parents[1]
MEASURED_F1 = {30: 16.49, 50: 6.02}  # the data README (authors' FFT peaks)


def beam_record(length_cm: int) -> wi.WhiskerRecord:
    """The nominal record of the beam (README values; accelerometer 6 cm from the tip)."""
    length = length_cm / 100
    return wi.WhiskerRecord(
        name=f"cantilever-aluminium-{length_cm}cm",
        description=(
            f"Aluminium cantilever 50 x 2 mm, {length_cm} cm free length, 5 g ADXL357 treated as "
            "a tip mass, accelerometer 6 cm from the free end (EnesDemirkaya/"
            "Vibration-Tester-ADXL357-FFT, MIT). Calibrated by examples/calibrate_cantilever.py."
        ),
        structure=wi.UniformBeam(
            length_m=length,
            youngs_modulus_pa=70e9,
            density_kg_m3=2700.0,
            section="rectangular",
            width_m=0.05,
            thickness_m=0.002,
        ),
        zeta=0.01,
        n_modes=1,
        tip_mass_kg=0.005,
        sensor_position_m=length - 0.06,
    )


def observation(path: Path) -> wi.Observation:
    a = np.load(path)
    obs = wi.Observation(
        a[0], a[1] * G0, observable="acceleration", name=path.name, source=str(path)
    )
    return obs.window(release_time(obs.t, obs.y), None)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "cantilever")
    ap.add_argument("--out", type=Path, default=Path("calibrate-cantilever"))
    ap.add_argument("--fits", type=Path, default=ROOT / "fits")
    ap.add_argument("--modes", type=int, default=1)
    args = ap.parse_args(argv)
    if not args.data.exists():
        print(f"no data at {args.data}", file=sys.stderr)
        return 2
    from whiskerid.plot import plot_calibration

    summary = {}
    for length_cm in (30, 50):
        record = beam_record(length_cm)
        paths = sorted((args.data / f"{length_cm}cm").glob("*.npy"))
        obs = [observation(p) for p in paths]
        rows = []
        for o in obs:
            cal = wi.calibrate(record, o, n_modes=args.modes)
            p = cal.params
            rows.append(
                {
                    "file": o.name,
                    "status": cal.status,
                    "f1_hz": p["f1_hz"]["value"],
                    "f1_std": p["f1_hz"]["std"],
                    "zeta": p["zeta"]["value"],
                    "zeta_std": p["zeta"]["std"],
                    "EI": p["EI"]["value"],
                    "rms_residual_m_s2": cal.diagnostics["rms_residual"][0],
                    "lag1_autocorr": cal.diagnostics["lag1_autocorr"][0],
                }
            )
            print(
                f"{length_cm} cm {o.name}: f1 = {rows[-1]['f1_hz']:.4f} Hz, "
                f"zeta = {rows[-1]['zeta']:.5f}",
                file=sys.stderr,
            )
        joint = wi.calibrate(record, obs, n_modes=args.modes)
        for f in joint.record.extra["fit"]["data_files"]:  # paths relative to the repo root
            f["path"] = os.path.relpath(f["path"], ROOT)
        joint.record.save(args.fits / f"{record.name}.toml")
        plot_calibration(args.out / f"{record.name}.png", joint)
        f1s = np.array([r["f1_hz"] for r in rows])
        zetas = np.array([r["zeta"] for r in rows])
        ei_nominal = record.structure.EI
        jp = joint.params
        summary[f"{length_cm}cm"] = {
            "recordings": rows,
            "f1_mean_hz": float(f1s.mean()),
            "f1_spread_hz": float(f1s.std(ddof=1)),
            "f1_measured_hz": MEASURED_F1[length_cm],
            "f1_error_vs_measured": float(f1s.mean() / MEASURED_F1[length_cm] - 1),
            "zeta_mean": float(zetas.mean()),
            "zeta_spread": float(zetas.std(ddof=1)),
            "joint": {k: {"value": v["value"], "std": v["std"]} for k, v in jp.items()},
            "joint_status": joint.status,
            "EI_nominal": ei_nominal,
            "EI_error_vs_nominal": float(jp["EI"]["value"] / ei_nominal - 1),
            "record": str(args.fits / f"{record.name}.toml"),
        }
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
