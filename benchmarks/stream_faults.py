"""Stream fault benchmark: what the stream labels and says under each emulated fault.

Runs the stream loop (``Sampler`` -> ``ADS1115`` -> emulated chip fed by the terrain
simulator, virtual clock, model inline) for ``--duration`` seconds per fault: none, a chip
stuck at one code, conversions that never finish, 50 % bus errors, 3 ms slow reads, 20 %
bus errors that are not OSErrors, and a model that returns NaN. Prints one line per fault
(samples, gaps, overruns, label counts, fault episodes) and the first thing it said.

    python benchmarks/stream_faults.py --model MODEL
"""

from __future__ import annotations

import argparse

import numpy as np
from whiskerid.hw import OnlineClassifier, run_stream, terrain_source

from whiskerid import hw, paper_record
from whiskerid.classify import ClassifierModel


class NaNModel:
    """A model whose weights went NaN: every output is NaN."""

    def __init__(self, model):
        self.model = model

    def __getattr__(self, name):
        return getattr(self.model, name)

    def window_proba(self, samples, speed=None):
        return np.full(len(self.model.labels), np.nan)


def _stuck(chip):
    chip.stuck_code = 13_000


def _never(chip):
    chip.never_ready = True


def _errors(chip):
    chip.error_rate = 0.5


def _slow(chip):
    chip.read_delay_s = 3e-3


def _odd(chip):
    chip.error_rate, chip.error = 0.2, RuntimeError("bus glitch")


FAULTS = [("none", None), ("stuck code", _stuck), ("never ready", _never),
          ("50% bus errors", _errors), ("3 ms slow reads", _slow),
          ("20% non-OSError errors", _odd), ("NaN model", None)]  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="trained model folder")
    p.add_argument("--terrain", default="brick", help="simulated terrain (a label of the model)")
    p.add_argument("--duration", type=float, default=20.0, help="seconds per fault")
    args = p.parse_args(argv)
    model = ClassifierModel.load(args.model)
    source = terrain_source(paper_record(), args.terrain, 0.2, args.duration + 2, seed=1)
    for name, fault in FAULTS:
        clock = hw.FakeClock()
        timing = {"clock": clock.now_ns, "sleep": clock.sleep}
        chip = hw.EmulatedADS1115(source, seed=1, noise_v=1e-4, **timing)
        if fault is not None:
            fault(chip)
        sampler = hw.Sampler(hw.ADS1115(chip, **timing), 200.0, **timing)
        said: list[str] = []
        summary = hw.StreamSummary()

        def on_label(w, summary=summary, said=said):
            if summary.add(w) == "start":
                said.append(f"t = {w.t_end_s:.1f} s  {w.label}: {w.reason}")

        used = NaNModel(model) if name == "NaN model" else model
        out = run_stream(sampler.samples(duration_s=args.duration, gaps=True),
                         OnlineClassifier(used, hop_s=0.5, speed_mps=0.2), on_label=on_label,
                         background=False)  # fmt: skip
        d = summary.to_dict()
        st = sampler.stats
        print(f"{name:24s} samples {out.samples:5d} gaps {st.gaps:5d} overruns {st.overruns:5d} "
              f"labels {d['label_counts']} episodes {d['fault_episodes']}")  # fmt: skip
        for line in said[:1]:
            print(f"    says: {line}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
