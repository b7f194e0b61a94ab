"""The paper's modal analysis, reproduced with both models (Section III, Figs. 'vibration' and
'surf').

For the paper's whisker (sensor at x_s = 5 mm) this script computes, for base excitation
y_b = h_b sin(2π f_b t):

1. the sensor displacement and its spectrum at h_b = 0.1/0.3 mm and f_b = 100/300 Hz
   (paper Eq. 1 as printed, and the exact modal model's steady state);
2. the maximum sensor displacement y_s,max and the dominant frequency f_s,max over a grid of
   f_b (5–500 Hz) and h_b (0.1–0.5 mm), vectorised with ``jax.vmap``.

It prints a JSON summary and saves ``modal_analysis_paper.png``, ``modal_analysis_exact.png``
and ``ys_max_vs_fb.png`` in --out.

Run: ``python examples/modal_analysis.py --out modal-analysis``
"""

import argparse
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import whiskerid as wi
from whiskerid.plot._plot import _pyplot, plot_modal_analysis

RATE = 20_000.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("modal-analysis"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    w = wi.paper_whisker()
    t = jnp.arange(0, 1.0, 1 / RATE)

    def paper(fb, hb):
        return wi.paper_eq1(w, t, fb_hz=fb, hb_m=hb)

    def exact(fb, hb):
        return wi.observe(w, wi.harmonic_steady_state(w, t, fb_hz=fb, hb_m=hb))

    cases = {"paper": [], "exact": []}
    for fb in (100.0, 300.0):
        for hb in (1e-4, 3e-4):
            for name, fn in (("paper", paper), ("exact", exact)):
                cases[name].append({"t": np.asarray(t), "y": np.asarray(fn(fb, hb)), "hb_m": hb,
                                    "fb_hz": fb, "model": name})  # fmt: skip
    for name, rows in cases.items():
        plot_modal_analysis(args.out / f"modal_analysis_{name}.png", rows)

    fbs = jnp.linspace(5.0, 500.0, 100)
    hbs = jnp.array([1e-4, 3e-4, 5e-4])
    summary = {"f_natural_hz": [round(float(f), 2) for f in w.natural_frequencies_hz]}
    plt = _pyplot()
    fig, (ax_y, ax_f) = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for name, fn in (("paper", paper), ("exact", exact)):
        grid = jax.jit(jax.vmap(jax.vmap(fn, (0, None)), (None, 0)))(fbs, hbs)  # (hb, fb, t)
        ys_max = np.asarray(jnp.max(jnp.abs(grid), axis=-1))
        spec = np.abs(np.fft.rfft(np.asarray(grid) - np.asarray(grid).mean(-1, keepdims=True)))
        f_dom = np.fft.rfftfreq(t.size, 1 / RATE)[np.argmax(spec, axis=-1)]
        summary[name] = {
            "dominant_equals_fb_everywhere": bool(np.all(np.abs(f_dom - np.asarray(fbs)) <= 1.0)),
            "ys_max_um_at_hb_0.1mm": {f"{float(f):.0f}": round(float(y) * 1e6, 3)
                                      for f, y in zip(fbs[::11], ys_max[0, ::11], strict=True)},
        }  # fmt: skip
        for i, hb in enumerate(hbs):
            style = "-" if name == "exact" else "--"
            ax_y.semilogy(fbs, ys_max[i], style, label=f"{name}, h_b = {float(hb) * 1e3:g} mm")
            ax_f.plot(fbs, f_dom[i], style, label=f"{name}, h_b = {float(hb) * 1e3:g} mm")
    ax_y.set_xlabel("f_b (Hz)")
    ax_y.set_ylabel("y_s,max (m)")
    ax_f.set_xlabel("f_b (Hz)")
    ax_f.set_ylabel("dominant frequency f_s,max (Hz)")
    ax_y.legend(fontsize=7)
    fig.savefig(args.out / "ys_max_vs_fb.png", dpi=110)
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
