"""Benchmark: fleet calibration and change detection on a simulated fleet, and on real repeats.

A simulated fleet (:func:`whiskerid.fleet.simulate_fleet`: coil whiskers with their own
geometry, material and ζ, records at the nominal values, held, flicked and tapped plucks read
by the ADS1115 at 860 Hz, SNR 35 dB, f_1 and ζ moving a little from session to session) of
``--whiskers`` × ``--sessions`` × ``--plucks``, ``--damaged`` whiskers changed (ζ × 1.5 or
f_1 × 0.97, alternately) from a random session after the baseline on, is calibrated by
``whiskerid fleet calibrate`` (one process, timed from the command's start, JAX's start and
compilations included) and checked by :func:`whiskerid.fleet.check_fleet`:

* detection rate: damaged whiskers whose damaged parameter is found changed, and how many of
  those changes are located at the session where the damage began;
* false alarms: flagged whisker-sessions among the checked ones that are not damaged;
* throughput against a shell loop of ``whiskerid calibrate`` (one process per session, all of
  its plucks jointly, as a user would script it): the loop is timed on ``--loop-sample``
  sessions and scaled to the fleet (both use the same persistent compilation cache, warmed by
  the fleet run, which favours the loop); and fits per second.

With ``--cantilever DIR`` the real aluminium cantilever's repeats (30 cm and 50 cm, five
recordings each) are laid out as two whiskers whose repeats are sessions (links in a
temporary folder) with the records ``fits/cantilever-aluminium-*.toml``, calibrated (one
mode, acceleration in g) and checked: any flag there is a false alarm.

Progress goes to stderr (the fleet's own bar, then the loop's sessions) and ends with one
line that puts the fleet's time beside the loop's, wall and CPU (user + system: on a machine
shared with other work the wall times of the two depend on the load at the time each ran,
the CPU times far less), with the load averages; the JSON goes to stdout.

Run: ``python benchmarks/fleet.py [--whiskers 100 --sessions 10 --plucks 3 --damaged 10]
[--cantilever ../shared/data/cantilever]`` (prints JSON).
"""

import argparse
import json
import os
import platform
import random
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _detection(rows, truth, baseline):
    from whiskerid.fleet import check_fleet

    result = check_fleet(rows, baseline=baseline)
    flagged = {(f["whisker"], f["session"]) for f in result.flags}
    damaged = {(t["whisker"], t["session"]) for t in truth.sessions if t["damaged"]}
    checked = {(c["whisker"], c["session"]) for c in result.changes}
    param = {"zeta": "zeta", "f1": "f1_hz"}
    found = {(e["whisker"], e["parameter"]): e for e in result.events}
    detected = [w for w, (first, kind) in truth.damage.items() if (w, param[kind]) in found]
    located = [
        w for w in detected if found[(w, param[truth.damage[w][1]])]["began"] == truth.damage[w][0]
    ]
    healthy = checked - damaged
    false = flagged & healthy
    return {
        "damaged_whiskers": len(truth.damage),
        "detected": len(detected),
        "detection_rate": len(detected) / max(len(truth.damage), 1),
        "located_at_first_damaged_session": len(located),
        "damaged_sessions_flagged": len(flagged & damaged),
        "damaged_sessions_checked": len(checked & damaged),
        "checked_healthy_sessions": len(healthy),
        "false_alarms": len(false),
        "false_alarm_rate": len(false) / max(len(healthy), 1),
        "false_alarm_sessions": sorted(f"{w}/{s}" for w, s in false),
        "missed": sorted(set(truth.damage) - set(detected)),
        "events": result.events,
        "notes": result.notes,
    }  # fmt: skip


def _cli(*args, env, progress=False):
    """Run the CLI; with ``progress`` its stderr (the progress bar) goes to ours."""
    cmd = [sys.executable, "-m", "whiskerid.cli", *map(str, args)]
    t0, cpu0 = time.perf_counter(), _children_cpu()
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=None if progress else subprocess.PIPE,
                          text=True, env=env)  # fmt: skip
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{(proc.stderr or '')[-3000:]}")
    CPU.append(_children_cpu() - cpu0)
    return time.perf_counter() - t0, proc.stdout


#: CPU seconds (user + system) of each CLI run, in order: unlike the wall time, nearly the
#: same on a machine shared with other work (the load average is printed beside it).
CPU: list[float] = []


def _children_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _say(text: str) -> None:
    print(f"[fleet benchmark {time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


def simulated(args, work: Path, env) -> dict:
    from whiskerid.fleet import read_table, simulate_fleet

    t0 = time.perf_counter()
    truth = simulate_fleet(work / "root", whiskers=args.whiskers, sessions=args.sessions,
                           plucks=args.plucks, damaged=args.damaged, baseline=args.baseline,
                           seed=args.seed)  # fmt: skip
    sim_s = time.perf_counter() - t0
    n_total = args.whiskers * args.sessions
    _say(f"simulated {args.whiskers} x {args.sessions} x {args.plucks} in {sim_s:.0f} s; "
         f"fleet calibrate of {n_total} sessions (its progress bar below) ...")  # fmt: skip
    extra = ["--ray", args.ray] if args.ray else []
    fleet_s, out = _cli("fleet", "calibrate", work / "root", "--out", work / "out", "--json",
                        *extra, env=env, progress=True)  # fmt: skip
    fleet_cpu, load_fleet = CPU[-1], os.getloadavg()[1]
    _say(f"fleet calibrate: {fleet_s:.0f} s ({fleet_cpu:.0f} s CPU) for {n_total} sessions")
    summary = json.loads(out)
    rows = read_table(work / "out" / "fleet.csv")
    n_sessions = len(rows)
    plucks = sum(int(r["n_plucks"] or 0) for r in rows)
    # the shell loop, on a sample of sessions
    rng = random.Random(args.seed)
    sample = rng.sample(rows, min(args.loop_sample, n_sessions))
    loop_s, loop_cpu = 0.0, 0.0
    for i, r in enumerate(sample):
        _say(f"shell loop: whiskerid calibrate of session {i + 1}/{len(sample)} "
             f"({loop_s:.0f} s so far)")  # fmt: skip
        folder = work / "root" / r["whisker"] / r["session"]
        files = sorted(folder.glob("*.csv"))
        dt, _ = _cli("calibrate", *files, "--whisker", work / "root" / r["whisker"] /
                     "whisker.toml", "--out", work / "loop" / f"{r['whisker']}-{r['session']}.toml",
                     env=env)  # fmt: skip
        loop_s += dt
        loop_cpu += CPU[-1]
    loop_per_session = loop_s / max(len(sample), 1)
    loop_cpu_per_session = loop_cpu / max(len(sample), 1)
    load_loop = os.getloadavg()[1]
    _say(f"fleet calibrate {fleet_s:.0f} s wall, {fleet_cpu:.0f} s CPU (load {load_fleet:.1f}) | "
         f"shell loop {loop_per_session:.1f} s wall, {loop_cpu_per_session:.1f} s CPU a session "
         f"x {n_sessions} (timed on {len(sample)}; load {load_loop:.1f}) | "
         f"{loop_per_session * n_sessions / fleet_s:.1f}x wall, "
         f"{loop_cpu_per_session * n_sessions / max(fleet_cpu, 1e-9):.1f}x CPU")  # fmt: skip
    # a rerun: nothing new
    rerun_s, out2 = _cli("fleet", "calibrate", work / "root", "--out", work / "out", "--quiet",
                         "--json", env=env)  # fmt: skip
    return {
        "fleet": {
            "whiskers": args.whiskers,
            "sessions": args.sessions,
            "plucks": args.plucks,
            "damaged": args.damaged,
            "baseline": args.baseline,
            "seed": args.seed,
        },
        "simulate_s": round(sim_s, 1),
        "fleet_calibrate_s": round(fleet_s, 2),
        "fleet_fit_s": summary["elapsed_s"],
        "sessions_fitted": summary["fitted"],
        "sessions_not_ok": summary["failed"],
        "sessions_per_s": round(n_sessions / fleet_s, 3),
        "pluck_fits_per_s": round(plucks / fleet_s, 3),
        "fits_per_s_with_joint": round((plucks + n_sessions) / fleet_s, 3),
        "shell_loop_sample_sessions": len(sample),
        "shell_loop_s_per_session": round(loop_per_session, 3),
        "shell_loop_scaled_s": round(loop_per_session * n_sessions, 1),
        "speedup": round(loop_per_session * n_sessions / fleet_s, 2),
        "fleet_calibrate_cpu_s": round(fleet_cpu, 1),
        "shell_loop_cpu_s_per_session": round(loop_cpu_per_session, 2),
        "speedup_cpu": round(loop_cpu_per_session * n_sessions / max(fleet_cpu, 1e-9), 2),
        "load_average_5min": {"fleet": round(load_fleet, 1), "loop": round(load_loop, 1)},
        "rerun_s": round(rerun_s, 2),
        "rerun_fitted": json.loads(out2)["fitted"],
        **_detection(rows, truth, args.baseline),
    }


def cantilever(data: Path, work: Path) -> dict:
    from whiskerid.fleet import FleetSettings, calibrate_fleet, check_fleet

    root = work / "cantilever"
    shutil.rmtree(root, ignore_errors=True)
    for length in ("30cm", "50cm"):
        w = root / f"beam-{length}"
        w.mkdir(parents=True)
        os.symlink(ROOT / "fits" / f"cantilever-aluminium-{length}.toml", w / "whisker.toml")
        for k, f in enumerate(sorted((data / length).glob("*.npy"))):
            (w / f"repeat-{k + 1}").mkdir()
            os.symlink(f.resolve(), w / f"repeat-{k + 1}" / f.name)
    settings = FleetSettings(n_modes=1, observable="acceleration", units_g=True)
    t0 = time.perf_counter()
    run = calibrate_fleet(root, work / "cantilever-out", settings=settings)
    fit_s = time.perf_counter() - t0
    result = check_fleet(run.rows)
    return {
        "sessions": run.sessions,
        "fit_s": round(fit_s, 1),
        "statuses": sorted({r["status"] for r in run.rows}),
        "values": [
            {
                k: r[k]
                for k in (
                    "whisker",
                    "session",
                    "f1_hz",
                    "f1_std",
                    "zeta",
                    "zeta_std",
                    "uncertainty",
                    "n_plucks",
                )
            }
            for r in run.rows
        ],
        "checked": len(result.changes),
        "flags": result.flags,
        "z": [
            {
                k: (round(c[k], 3) if isinstance(c[k], float) else c[k])
                for k in ("whisker", "session", "parameter", "change_pct", "z")
            }
            for c in result.changes
        ],
        "notes": result.notes,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--whiskers", type=int, default=100)
    ap.add_argument("--sessions", type=int, default=10)
    ap.add_argument("--plucks", type=int, default=3)
    ap.add_argument("--damaged", type=int, default=10)
    ap.add_argument("--baseline", type=int, default=2,
                    help="first reference of the check; no damage starts before it")  # fmt: skip
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--loop-sample", type=int, default=10, help="sessions the shell loop times")
    ap.add_argument("--ray", help="pass --ray to fleet calibrate (e.g. local)")
    ap.add_argument("--cantilever", type=Path, help="the cantilever data folder (real repeats)")
    ap.add_argument("--no-sim", action="store_true", help="only the real data")
    ap.add_argument("--keep", type=Path,
                    help="work in this folder and keep it (the cantilever's fits are then "
                    "reused by a later run; the simulated fleet is always made anew)")  # fmt: skip
    args = ap.parse_args()
    out = {"python": platform.python_version(), "cpu": platform.processor() or platform.machine(),
           "cores": os.cpu_count()}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="whiskerid-fleet-bench-") as tmp:
        work = Path(tmp) if args.keep is None else args.keep
        for name in ("root", "out", "loop"):
            shutil.rmtree(work / name, ignore_errors=True)
        env = {**os.environ, "WHISKERID_COMPILE_CACHE": str(work / "jax-cache")}
        if not args.no_sim:
            out["simulated"] = simulated(args, work, env)
        if args.cantilever:
            out["cantilever"] = cantilever(args.cantilever, work)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
