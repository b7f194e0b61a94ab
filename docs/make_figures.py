"""Make the figures the documentation shows (docs/figures/*.png).

Runs ``whiskerid demo`` (the same stages as the command) into a temporary folder, keeps the
figures the guides show, and draws two more from the library: the aliasing of the paper
whisker's modes at 200 Hz, and an added-mass calibration (plucks without and with a tip
mass). Every figure is written at a modest resolution so each PNG stays small.

    .venv/bin/python docs/make_figures.py            # writes docs/figures/*.png
"""

import argparse
import shutil
import tempfile
from pathlib import Path

FIGURES = Path(__file__).resolve().parent / "figures"

# demo output -> the name the docs use
FROM_DEMO = {
    "modal_analysis_paper.png": "modal-analysis-paper.png",
    "modal_analysis_exact.png": "modal-analysis-exact.png",
    "pluck_adc.png": "pluck-adc.png",
    "sine30hz_adc.png": "sine-adc.png",
    "calibration.png": "calibration.png",
    "posterior_corner.png": "posterior-corner.png",
    "posterior_trace.png": "posterior-trace.png",
    "terrain_confusion.png": "terrain-confusion.png",
}
MAX_WIDTH_PX = 900


def shrink(src: Path, dst: Path) -> None:
    """Copy a PNG, scaled down to at most ``MAX_WIDTH_PX`` wide and palette-quantised."""
    from PIL import Image

    with Image.open(src) as im:
        im = im.convert("RGB")
        if im.width > MAX_WIDTH_PX:
            h = round(im.height * MAX_WIDTH_PX / im.width)
            im = im.resize((MAX_WIDTH_PX, h), Image.LANCZOS)
        # 128 colours are plenty for line plots and keep each file well under 300 KB.
        im.quantize(colors=128, method=Image.Quantize.MEDIANCUT).save(dst, optimize=True)


def aliasing_figure(path: Path) -> None:
    """The paper whisker's natural frequencies and where they appear when sampled at 200 Hz."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import whiskerid as wi

    rate_hz = 200.0
    f_n = [float(f) for f in wi.paper_record().whisker().natural_frequencies_hz]
    folded = [abs(f - rate_hz * round(f / rate_hz)) for f in f_n]
    fig, ax = plt.subplots(figsize=(7.5, 2.8), dpi=110)
    ax.axvspan(0, rate_hz / 2, color="tab:green", alpha=0.12, label="0 – Nyquist (100 Hz)")
    for i, (f, g) in enumerate(zip(f_n, folded, strict=True), start=1):
        ax.annotate(
            "",
            xy=(g, 0.25),
            xytext=(f, 0.85),
            arrowprops={"arrowstyle": "->", "color": "0.5", "lw": 0.8},
        )
        ax.plot([f], [0.85], "o", color="tab:blue")
        ax.plot([g], [0.25], "s", color="tab:red")
        ax.text(f, 0.92, f"$f_{i}$ = {f:.0f}", ha="center", fontsize=8)
        # Stagger the folded labels: three of them land within a few hertz of each other.
        ax.text(g, 0.12 - 0.08 * (i % 2), f"{g:.0f}", ha="center", fontsize=8, color="tab:red")
    ax.set_xscale("symlog", linthresh=100)
    ax.set_xlim(0, 3000)
    ax.set_ylim(-0.02, 1.05)
    ax.set_yticks([])
    ax.set_xlabel("frequency (Hz)")
    ax.set_title(
        "Paper whisker: natural frequencies (blue) and where 200 Hz sampling shows them (red)"
    )
    ax.title.set_fontsize(9)
    ax.legend(loc="center right", fontsize=8, frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def added_mass_figure(path: Path) -> None:
    """The paper whisker plucked without and with 0.52 g at its tip (ADS1115 at 200 Hz,
    emulated), calibrated by the added-mass method."""
    from whiskerid.fit import AddedMass, calibrate, observations_from_recording
    from whiskerid.model import paper_record, simulate_pluck
    from whiskerid.plot import plot_added_mass

    record = paper_record()
    mass = AddedMass(0.52e-3, 0.01e-3)
    obs, masses = [], []
    for seed, added in ((1, None), (2, mass)):
        rec = record if added is None else record.replace(tip_mass_kg=added.kg)
        sim, _ = simulate_pluck(rec, rate_hz=200.0, duration_s=3.0, seed=seed)
        got = observations_from_recording(sim, record, observable="adc", excitation="decay")
        obs += got
        masses += [added] * len(got)
    plot_added_mass(path, calibrate(record, obs, added_mass=masses))


def main() -> None:
    """Run the demo, keep its figures, draw the aliasing figure."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=FIGURES, help="folder for the PNGs")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    # As `whiskerid demo` does: a second run loads the compiled programs (before JAX starts).
    from whiskerid.cli._cache import enable_compile_cache

    enable_compile_cache()
    from whiskerid.cli._demo_stages import run_demo

    with tempfile.TemporaryDirectory() as tmp:
        run_demo(Path(tmp), plots=True)
        for src, dst in FROM_DEMO.items():
            shrink(Path(tmp) / src, args.out / dst)
        raw = Path(tmp) / "aliasing.png"
        aliasing_figure(raw)
        shrink(raw, args.out / "aliasing.png")
        raw = Path(tmp) / "added-mass.png"
        added_mass_figure(raw)
        shrink(raw, args.out / "added-mass.png")
    for png in sorted(args.out.glob("*.png")):
        print(f"{png}: {png.stat().st_size / 1024:.0f} KB")
    shutil.rmtree(args.out / "__pycache__", ignore_errors=True)


if __name__ == "__main__":
    main()
