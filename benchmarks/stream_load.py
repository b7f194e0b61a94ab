"""The stream under load: ``whiskerid stream`` in real time with every core busy, beside the
same stream on a quieter machine.

Runs ``whiskerid stream --replay REC --model MODEL --duration D --json`` (a recording played
through the emulated chip on the real clock, sampled by the stream's sampling process: the
path a Pi takes, without the chip) three ways, one after the other, with the compile cache
warm (a short run first fills it):

The stream runs at ``--nice`` (-5, as ``hw/whiskerid-stream.service`` runs it); its
sampling process raises itself further (real time where permitted).

* ``quiet``: nothing of ours besides it;
* ``loaded``: with one busy-loop process per core (``--busy``, default the number of
  cores), started before the stream and stopped after it;
* ``loaded_no_priority``: the same load with ``--priority none`` (the sampling process at
  the ordinary priority), for ``--peer-duration`` seconds: what the priority buys.

For each run it prints the samples delivered against those the schedule holds
(``duration x rate``), the sampler's skipped slots and the hand-off's drops, the windows per
label (a false ``sensor-fault`` would show there; ``no-data`` counts starved windows), the
seconds from the command's start to its first label and to its first terrain label, the
label latencies and the priority the sampling process got, as one JSON object, with the
machine's load average before each run (a shared machine is never quiet: say so).

    python benchmarks/stream_load.py --duration 600
    python benchmarks/stream_load.py --duration 60 --peer-duration 60 --model MODEL

Without ``--model`` a small two-terrain model is trained first (``dataset synth`` +
``train``, about a minute); without ``--replay`` a brick recording is made with
``whiskerid record --emulate brick --fast``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

BUSY = "while True:\n    pass\n"


def whiskerid(*argv: str) -> None:
    """Run a whiskerid command quietly; fail loudly."""
    done = subprocess.run([sys.executable, "-m", "whiskerid.cli", *argv], capture_output=True,
                          text=True)  # fmt: skip
    if done.returncode != 0:
        raise SystemExit(f"whiskerid {argv[0]} failed:\n{done.stderr}")


def make_model(folder: Path) -> Path:
    """A small model (brick and sand at 0.2 m/s), as the tests train."""
    ds, model = folder / "ds", folder / "model"
    whiskerid("dataset", "synth", "--out", str(ds), "--terrains", "brick", "sand", "--speeds",
              "0.2", "--runs", "2", "--duration", "15", "--seed", "3")  # fmt: skip
    whiskerid("train", str(ds), "--out", str(model), "--seed", "0")
    return model


def one_stream(argv: list[str], *, busy: int) -> dict:
    """One stream, with ``busy`` busy-loop processes running through it."""
    load_before = os.getloadavg()
    hogs = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(busy)]
    try:
        time.sleep(1.0 if busy else 0.0)  # the load is there before the stream starts
        start = time.perf_counter()
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        first: list[float] = []
        terrain: list[float] = []
        lines: list[str] = []

        def read_stderr() -> None:
            assert proc.stderr is not None
            for line in proc.stderr:
                lines.append(line)
                if line.startswith("t = "):
                    now = time.perf_counter() - start
                    if not first:
                        first.append(now)
                    if " p = " in line and not terrain:
                        terrain.append(now)

        reader = threading.Thread(target=read_stderr, daemon=True)
        reader.start()
        stdout, _ = proc.communicate()
        reader.join(10)
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    if proc.returncode != 0:
        raise SystemExit(f"the stream failed ({proc.returncode}):\n{''.join(lines[-20:])}")
    out = json.loads(stdout)
    return _figures(out, first, terrain, busy, load_before)


def _figures(out: dict, first: list, terrain: list, busy: int, load_before) -> dict:
    counts = out["label_counts"]
    return {
        "busy_processes": busy,
        "loadavg_1min_before": round(load_before[0], 2),
        "samples": out["samples"],
        "first_label_s": round(first[0], 3) if first else None,
        "first_terrain_s": round(terrain[0], 3) if terrain else None,
        "windows": out["windows"],
        "label_counts": counts,
        "sensor_fault_windows": counts.get("sensor-fault", 0),
        "no_data_windows": counts.get("no-data", 0),
        "faults": out["faults"],
        "gaps": out["gaps"],
        "overruns": out["overruns"],
        "skipped_slots": out["sampling"].get("skipped_slots"),
        "priority": out["sampling"].get("priority"),
        "handoff": out["sampling"].get("handoff"),
        "dropped_windows": out["dropped_windows"],
        "latency_ms": out["latency_ms"],
        "fraction_correct": out.get("fraction_correct"),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=600.0, help="seconds per stream (600)")
    p.add_argument("--peer-duration", type=float, default=120.0,
                   help="seconds of the loaded stream without priority (0: none)")  # fmt: skip
    p.add_argument("--busy", type=int, default=os.cpu_count() or 2,
                   help="busy-loop processes of the loaded runs (one per core)")  # fmt: skip
    p.add_argument("--model", help="trained model folder (default: train a small one)")
    p.add_argument("--replay", help="recording to replay (default: a simulated brick run)")
    p.add_argument("--rate", type=float, default=200.0, help="sampling rate (Hz)")
    p.add_argument("--nice", type=int, default=-5,
                   help="nice value of the stream, as the systemd unit sets it")  # fmt: skip
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="whiskerid-load-") as tmp:
        folder = Path(tmp)
        model = Path(args.model) if args.model else make_model(folder)
        longest = max(args.duration, args.peer_duration)
        replay = args.replay
        if replay is None:
            replay = str(folder / "brick.csv")
            whiskerid("record", replay, "--emulate", "brick", "--fast", "--duration",
                      f"{longest + 2:g}", "--speed", "0.2")  # fmt: skip
        cache = folder / "cache"
        base = ["nice", "-n", str(args.nice), str(Path(sys.executable).with_name("whiskerid")),
                "stream", "--model",
                str(model), "--replay", replay, "--json", "--compile-cache", str(cache),
                "--rate", f"{args.rate:g}"]  # fmt: skip
        one_stream([*base, "--duration", "3"], busy=0)  # fills the compile cache: warm runs
        runs = {}
        for name, duration, busy, extra in (
            ("quiet", args.duration, 0, []),
            ("loaded", args.duration, args.busy, []),
            ("loaded_no_priority", args.peer_duration, args.busy, ["--priority", "none"]),
        ):
            if duration <= 0:
                continue
            r = one_stream([*base, "--duration", f"{duration:g}", *extra], busy=busy)
            expected = round(duration * args.rate)
            r = {"duration_s": duration, "expected_samples": expected,
                 "delivered": round(r["samples"] / expected, 5), **r}  # fmt: skip
            runs[name] = r
    out = {
        "cores": os.cpu_count(),
        "stream_nice": args.nice,
        "note": "a shared machine: other users' work is load on every run, 'quiet' included",
        "targets": {"delivered": ">= 0.995", "sensor_fault_windows": 0, "first_label_s": "<= 2"},
        **runs,
    }
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
