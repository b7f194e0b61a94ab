"""Benchmark: how often `fleet check` finds a lasting change, where it began, and how often
it flags a healthy whisker-session: seeded fleets drawn here, at the table's level.

Each fleet has ``--whiskers`` whiskers of ``--sessions`` sessions of ``--plucks`` plucks; a
whisker's f1 is drawn in 40-50 Hz and its ζ around 0.04, each session moves them by
``--day-f1`` and ``--day-zeta`` (relative standard deviations: the mount, the temperature),
each pluck by ``--pluck-f1`` and ``--pluck-zeta`` around its session, and each session's fit
reports a 1σ of 0.01 % (f1) and 1 % (ζ), as the fleet's single-pluck fits of simulated
ADS1115 recordings do. Scenarios, each over ``--seeds`` seeds:

* ``healthy``: no whisker changes; every flag is a false alarm;
* ``step f1 x0.97 @ s`` and ``step zeta x1.5 @ s``: one whisker in four changes from session
  ``s`` on, for every ``s`` from the first reference's end to the last session;
* ``drift f1 -0.3 %/session`` and ``drift zeta +6 %/session`` from session 3 on.

Per scenario: ``detected`` (changed whiskers whose changed parameter is found), ``located``
(found where the change began), ``delay`` (mean sessions from the change to the session that
found it), ``false_alarm_rate`` (flagged healthy whisker-sessions over those checked, with
the damaged whiskers' sessions before their change counted as healthy: a change located one
session early flags one), and the same for the whiskers that never changed alone.

Run: ``python benchmarks/fleet_detection.py [--seeds 10 --whiskers 20 --sessions 10]``
(prints JSON; about 30 s on an idle machine).
"""

import argparse
import json
import math
import time

import numpy as np


def fleet(rng, args, damage):
    """Table rows and the truth; ``damage``: whisker → (first session, parameter, how the
    factor grows with the sessions since the change)."""
    rows = []
    for w in range(args.whiskers):
        f1_w, zeta_w = rng.uniform(40, 50), 0.04 * math.exp(rng.normal(0, 0.25))
        first, param, factor = damage.get(w, (args.sessions, None, None))
        for s in range(args.sessions):
            f1 = f1_w * (1 + args.day_f1 * rng.normal())
            zeta = zeta_w * math.exp(args.day_zeta * rng.normal())
            if s >= first:
                k = factor(s - first + 1)
                f1, zeta = (f1 * k, zeta) if param == "f1_hz" else (f1, zeta * k)
            f1_k = f1 * (1 + args.pluck_f1 * rng.normal(size=args.plucks))
            zeta_k = zeta * (1 + args.pluck_zeta * rng.normal(size=args.plucks))
            rows.append({
                "whisker": f"w{w:03d}", "session": f"s{s:02d}", "status": "ok",
                "f1_hz": repr(float(f1_k.mean())), "f1_std": repr(1e-4 * f1),
                "zeta": repr(float(zeta_k.mean())), "zeta_std": repr(0.01 * zeta),
                "f1_plucks": ";".join(map(repr, f1_k)),
                "zeta_plucks": ";".join(map(repr, zeta_k)),
                "pluck_status": ";".join(["ok"] * args.plucks),
            })  # fmt: skip
    return rows


def score(rows, damage, args) -> dict:
    from whiskerid.fleet import check_fleet

    result = check_fleet(rows, baseline=args.baseline)
    found = {(e["whisker"], e["parameter"]): e for e in result.events}
    changed = {f"w{w:03d}": d for w, d in damage.items()}
    hits = [(w, found[(w, d[1])]) for w, d in changed.items() if (w, d[1]) in found]
    located = sum(e["began"] == f"s{changed[w][0]:02d}" for w, e in hits)
    delays = [int(e["detected"][1:]) - changed[w][0] for w, e in hits]
    damaged = {(w, f"s{s:02d}") for w, d in changed.items() for s in range(d[0], args.sessions)}
    checked = {(c["whisker"], c["session"]) for c in result.changes}
    flagged = {(f["whisker"], f["session"]) for f in result.flags}
    healthy = checked - damaged
    others = {(w, s) for w, s in healthy if w not in changed}
    return {"changed": len(changed), "detected": len(hits), "located": located,
            "delays": delays, "healthy": len(healthy), "false": len(flagged & healthy),
            "others": len(others), "false_others": len(flagged & others)}  # fmt: skip


def scenarios(args):
    step = {"f1_hz": 0.97, "zeta": 1.5}
    out = [("healthy", None, None, None)]
    for p, k in step.items():
        for s in range(args.baseline, args.sessions):
            out.append((f"step {'f1' if p == 'f1_hz' else 'zeta'} x{k} @ s{s:02d}", s, p,
                        (lambda n, k=k: k)))  # fmt: skip
    out.append(("drift f1 -0.3 %/session @ s03", 3, "f1_hz", lambda n: 1 - 0.003 * n))
    out.append(("drift zeta +6 %/session @ s03", 3, "zeta", lambda n: 1 + 0.06 * n))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--whiskers", type=int, default=20)
    ap.add_argument("--sessions", type=int, default=10)
    ap.add_argument("--plucks", type=int, default=3)
    ap.add_argument("--baseline", type=int, default=2)
    ap.add_argument("--day-f1", type=float, default=0.002)
    ap.add_argument("--day-zeta", type=float, default=0.05)
    ap.add_argument("--pluck-f1", type=float, default=0.0005)
    ap.add_argument("--pluck-zeta", type=float, default=0.04)
    args = ap.parse_args()
    t0 = time.perf_counter()
    table = []
    for name, first, param, factor in scenarios(args):
        total = {"changed": 0, "detected": 0, "located": 0, "delays": [], "healthy": 0,
                 "false": 0, "others": 0, "false_others": 0}  # fmt: skip
        for seed in range(args.seeds):
            rng = np.random.default_rng([seed, len(table)])
            hit = rng.choice(args.whiskers, size=args.whiskers // 4, replace=False)
            damage = {} if param is None else {int(w): (first, param, factor) for w in hit}
            r = score(fleet(rng, args, damage), damage, args)
            for k in total:
                total[k] += r[k]
        n = max(total["changed"], 1)
        table.append({
            "scenario": name,
            "changed_whiskers": total["changed"],
            "detection_rate": round(total["detected"] / n, 3) if param else None,
            "located_rate": round(total["located"] / n, 3) if param else None,
            "mean_delay_sessions": (round(float(np.mean(total["delays"])), 2)
                                    if total["delays"] else None),
            "healthy_whisker_sessions": total["healthy"],
            "false_alarms": total["false"],
            "false_alarm_rate": round(total["false"] / max(total["healthy"], 1), 5),
            "unchanged_whiskers_sessions": total["others"],
            "false_alarms_unchanged_whiskers": total["false_others"],
        })  # fmt: skip
    healthy = sum(r["healthy_whisker_sessions"] for r in table)
    false = sum(r["false_alarms"] for r in table)
    print(json.dumps({"settings": vars(args), "seconds": round(time.perf_counter() - t0, 1),
                      "false_alarm_rate_all": round(false / healthy, 5),
                      "healthy_whisker_sessions_all": healthy, "table": table},
                     indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
