"""Start-up benchmark: time from ``whiskerid stream`` to its first label, and its memory.

Runs ``whiskerid stream --replay REC --model MODEL`` (a replayed recording through the
emulated chip, in real time: what a restarted service does, without a robot) with a fresh
JAX compilation cache folder: the first run compiles (cold), the next ones load the compiled
functions from the cache (warm: ``--warm-runs``, median and range). A last run with the
cache off shows what the cache saves. For each run it prints the seconds from process start
to the first label line on stderr (``first_label_s``, which may be a fault such as
``no-data``) and to the first terrain label (``first_terrain_s``), and the peak resident
memory (VmHWM) of the stream's process and of its sampling process, as one JSON object.
``after_window_s`` is the first label's time less its window's end in stream time: at most
how long the label came after its window filled (sampling starts after the process does).
``--exe`` times another build's ``whiskerid`` (the one before a change) in the same run.

    python benchmarks/stream_startup.py --model MODEL --replay REC.csv
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path


def peak_rss_mib(pid: int) -> float | None:
    """The process's peak resident memory (VmHWM) in MiB, or None once it has gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def children(pid: int) -> list[int]:
    """The process's child processes (its sampling process)."""
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(c) for c in f.read().split()]
    except OSError:
        return []


def one_run(argv: list[str]) -> dict:
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    first: list[float] = []
    window_end: list[float] = []
    terrain: list[float] = []
    peak = [0.0, 0.0]

    done = threading.Event()

    def watch():
        while not done.is_set():  # not proc.poll(): it would reap the process before wait4
            peak[0] = max(peak[0], peak_rss_mib(proc.pid) or 0.0)
            kids = sum(peak_rss_mib(c) or 0.0 for c in children(proc.pid))
            peak[1] = max(peak[1], kids)
            time.sleep(0.05)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    assert proc.stderr is not None
    for line in proc.stderr:
        if line.startswith("t = "):
            now = time.perf_counter() - start
            if not first:
                first.append(now)
                window_end.append(float(line.split()[2]))  # "t = 1.00 s ..."
            if " p = " in line and not terrain:  # a terrain, not a fault or no-data label
                terrain.append(now)
    _, status, usage = os.wait4(proc.pid, 0)  # its CPU, with its sampling process's
    proc.returncode = os.waitstatus_to_exitcode(status)
    done.set()
    watcher.join()
    return {
        "first_label_s": round(first[0], 3) if first else None,
        "first_terrain_s": round(terrain[0], 3) if terrain else None,
        # The first label's window ended that many seconds after sampling started, so at
        # least that long after the process did: what is left is the most the label took
        # after its window filled.
        "after_window_s": round(first[0] - window_end[0], 3) if first else None,
        "total_s": round(time.perf_counter() - start, 3),
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 3),
        "peak_rss_mib": round(peak[0], 1),
        "sampler_peak_rss_mib": round(peak[1], 1),
        "exit": proc.returncode,
    }


def _summary(runs: list[dict]) -> dict:
    """Median and range of several runs' figures."""
    out = {"runs": len(runs), "exit": max(r["exit"] for r in runs)}
    for key in (
        "first_label_s",
        "first_terrain_s",
        "after_window_s",
        "total_s",
        "cpu_s",
        "peak_rss_mib",
        "sampler_peak_rss_mib",
    ):
        v = sorted(r[key] for r in runs if r[key] is not None)
        if v:
            out[key] = round(statistics.median(v), 3)
            out[key + "_range"] = [v[0], v[-1]]
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="trained model folder")
    p.add_argument("--replay", required=True, help="recording to replay")
    p.add_argument("--duration", type=float, default=3.0, help="seconds streamed per run")
    p.add_argument("--warm-runs", type=int, default=5,
                   help="warm starts to time (their median and range are reported)")  # fmt: skip
    p.add_argument("--exe", default=str(Path(sys.executable).with_name("whiskerid")),
                   help="the whiskerid command to time (another build's, to compare)")  # fmt: skip
    args = p.parse_args(argv)
    exe = args.exe
    cache = Path(tempfile.mkdtemp(prefix="whiskerid-jax-"))
    base = [str(exe), "stream", "--model", args.model, "--replay", args.replay,
            "--duration", str(args.duration)]  # fmt: skip
    try:
        out = {
            "cold": one_run([*base, "--compile-cache", str(cache)]),
            "warm": _summary(
                [one_run([*base, "--compile-cache", str(cache)]) for _ in range(args.warm_runs)]
            ),
            "no_cache": one_run([*base, "--compile-cache", "none"]),
            "load_avg": os.getloadavg(),
            "cache_files": sum(1 for _ in cache.rglob("*") if _.is_file()),
        }
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
