"""Benchmark: 10 s at 200 Hz of the exact modal model, JAX (jit, vmap) against plain NumPy.

Two forms of the exact model are timed on the paper whisker (5 modes, sensor at 5 mm):

* ``sine_from_rest``: closed form, base ``h_b sin(2π f_b t)`` switched on at t = 0;
* ``base_motion``: the per-mode exact discretisation driven by a sampled base acceleration
  (``lax.scan`` in JAX; a Python loop over time steps, vectorised over modes and parameter
  sets, in NumPy).

For each: compile time, warm time of one evaluation, and warm time for 1000 parameter sets
(EI and ζ varied) with ``jax.vmap`` against NumPy (a loop over sets, and a broadcast version
where the form allows it). The NumPy code is an independent transcription of the same
equations (including the static correction), and the outputs are compared.

Run: ``python benchmarks/model.py`` (prints one JSON object).
"""

import json
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

import whiskerid as wi

RATE, DURATION, N_SETS = 200.0, 10.0, 1000
FB, HB = 30.0, 1e-4
BETA0 = np.array(
    [
        1.8751040687119611,
        4.6940911329741745,
        7.8547574382376126,
        10.995540734875467,
        14.137168391046471,
    ]
)


def _best(fn, repeat=5):
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - start)
    return min(times)


# ----------------------------------------------------------------------------- NumPy model
def np_modal(ei, rho_a, length, x):
    """ω, Γ, φ(x) and the static correction R(x) of a cantilever without tip mass."""
    b = BETA0
    sigma = (np.cosh(b) + np.cos(b)) / (np.sinh(b) + np.sin(b))
    z = b * x / length
    phi = np.cosh(z) - np.cos(z) - sigma * (np.sinh(z) - np.sin(z))
    gamma = 2 * sigma / b
    omega = b**2 * np.sqrt(ei / rho_a) / length**2
    static = rho_a * x**2 * (6 * length**2 - 4 * length * x + x**2) / (24 * ei)
    return omega, gamma, phi, static - np.sum(gamma * phi / omega**2)


def np_sine_from_rest(t, ei, rho_a, zeta, length=0.06, x=0.005):
    omega, gamma, phi, resid = np_modal(ei, rho_a, length, x)
    wb = 2 * np.pi * FB
    a, bb = omega**2 - wb**2, 2 * zeta * omega * wb
    k = gamma * HB * wb**2 / (a**2 + bb**2)
    tt = t[:, None]
    q_ss = k * (a * np.sin(wb * tt) - bb * np.cos(wb * tt))
    q0, v0 = k * bb, -k * wb * a
    wd = omega * np.sqrt(1 - zeta**2)
    decay = np.exp(-zeta * omega * tt)
    q_tr = decay * (q0 * np.cos(wd * tt) + (v0 + zeta * omega * q0) / wd * np.sin(wd * tt))
    base_acc = -HB * wb**2 * np.sin(wb * t)
    return (q_ss + q_tr) @ phi - base_acc * resid


def np_base_motion(t, acc, ei, rho_a, zeta, length=0.06, x=0.005):
    """ei, rho_a, zeta: arrays of shape (sets,); returns (sets, samples)."""
    modal = [np_modal(e, r, length, x) for e, r in zip(ei, rho_a, strict=True)]
    omega = np.array([m[0] for m in modal])  # (sets, modes)
    gamma, phi = modal[0][1], np.array([m[2] for m in modal])
    resid = np.array([m[3] for m in modal])
    z = np.asarray(zeta)[:, None]
    wd = omega * np.sqrt(1 - z**2)
    u = -acc[:, None, None] * gamma  # (samples, 1, modes)
    q = np.zeros_like(omega)
    v = np.zeros_like(omega)
    out = np.zeros((omega.shape[0], t.size))
    for k in range(t.size - 1):
        h = t[k + 1] - t[k]
        slope = (u[k + 1] - u[k]) / h
        c1 = slope / omega**2
        c0 = u[k] / omega**2 - 2 * z * slope / omega**3
        dq, dv = q - c0, v - c1
        e, c, s = np.exp(-z * omega * h), np.cos(wd * h), np.sin(wd * h)
        q = e * (dq * (c + z * omega / wd * s) + dv * s / wd) + c0 + c1 * h
        v = e * (-dq * omega**2 / wd * s + dv * (c - z * omega / wd * s)) + c1
        out[:, k + 1] = np.sum(q * phi, axis=1)
    return out - acc[None, :] * resid[:, None]


# ----------------------------------------------------------------------------- JAX model
def jax_whisker(ei, zeta, base):
    return wi.Whisker(length_m=base.length_m, EI=ei, rho_a=base.rho_a,
                      zeta=jnp.full(5, zeta), sensor_x_m=base.sensor_x_m)  # fmt: skip


def main() -> None:
    base = wi.paper_whisker()
    t_np = np.arange(round(RATE * DURATION)) / RATE
    t = jnp.asarray(t_np)
    rng = np.random.default_rng(0)
    ei_sets = float(base.EI) * rng.uniform(0.7, 1.3, N_SETS)
    zeta_sets = rng.uniform(0.01, 0.1, N_SETS)
    rho_a = float(base.rho_a)
    acc_np = 3.0 * np.sin(2 * np.pi * 17 * t_np) + 2.0 * np.sin(2 * np.pi * 61 * t_np + 0.3)
    acc = jnp.asarray(acc_np)

    def sine(ei, zeta):
        w = jax_whisker(ei, zeta, base)
        return wi.observe(w, wi.harmonic_from_rest(w, t, fb_hz=FB, hb_m=HB))

    def scan(ei, zeta):
        w = jax_whisker(ei, zeta, base)
        return wi.observe(w, wi.base_motion_response(w, t, acc, uniform=True))

    results = {}
    for name, fn in (("sine_from_rest", sine), ("base_motion", scan)):
        single = jax.jit(fn)
        batch = jax.jit(jax.vmap(fn))
        e0, z0 = jnp.asarray(ei_sets[0]), jnp.asarray(zeta_sets[0])
        es, zs = jnp.asarray(ei_sets), jnp.asarray(zeta_sets)
        start = time.perf_counter()
        jax.block_until_ready(single(e0, z0))
        compile_single = time.perf_counter() - start
        start = time.perf_counter()
        jax.block_until_ready(batch(es, zs))
        compile_batch = time.perf_counter() - start
        t_single = _best(lambda: single(e0, z0), 20)  # noqa: B023 (called at once)
        t_batch = _best(lambda: batch(es, zs), 3)  # noqa: B023

        if name == "sine_from_rest":
            np_one = lambda: np_sine_from_rest(t_np, ei_sets[0], rho_a, zeta_sets[0])
            np_loop = lambda: [np_sine_from_rest(t_np, e, rho_a, z)
                               for e, z in zip(ei_sets, zeta_sets, strict=True)]  # fmt: skip
            np_vec = None
        else:
            np_one = lambda: np_base_motion(t_np, acc_np, ei_sets[:1], [rho_a], zeta_sets[:1])
            np_loop = None  # the broadcast form below is NumPy's best for this recurrence
            np_vec = lambda: np_base_motion(t_np, acc_np, ei_sets, [rho_a] * N_SETS, zeta_sets)
        ref_one = np.asarray(np_one()).reshape(-1)
        err = float(np.max(np.abs(np.asarray(single(e0, z0)) - ref_one)) / np.max(np.abs(ref_one)))
        t_np_one = _best(np_one, 5 if name == "sine_from_rest" else 2)
        entry = {
            "samples": int(t_np.size),
            "compile_s": {"single": round(compile_single, 3), "vmap_1000": round(compile_batch, 3)},
            "jax_single_warm_ms": round(t_single * 1e3, 4),
            "numpy_single_ms": round(t_np_one * 1e3, 4),
            "jax_vmap_1000_warm_ms": round(t_batch * 1e3, 3),
            "max_relative_difference_jax_vs_numpy": err,
        }
        if np_loop is not None:
            entry["numpy_loop_1000_ms"] = round(_best(np_loop, 2) * 1e3, 3)
            entry["speedup_vmap_vs_numpy_loop"] = round(entry["numpy_loop_1000_ms"] / entry[
                "jax_vmap_1000_warm_ms"], 2)  # fmt: skip
        if np_vec is not None:
            entry["numpy_broadcast_1000_ms"] = round(_best(np_vec, 1) * 1e3, 3)
            entry["speedup_vmap_vs_numpy_broadcast"] = round(
                entry["numpy_broadcast_1000_ms"] / entry["jax_vmap_1000_warm_ms"], 2
            )
        entry["speedup_single_vs_numpy"] = round(t_np_one / t_single, 2)
        results[name] = entry

    print(json.dumps({
        "benchmark": "model",
        "what": f"{DURATION:g} s at {RATE:g} Hz, paper whisker, 5 modes, {N_SETS} parameter sets",
        "jax": jax.__version__, "numpy": np.__version__, "device": str(jax.devices()[0]),
        "machine": platform.machine(), "python": platform.python_version(),
        "results": results,
    }, indent=2))  # fmt: skip


if __name__ == "__main__":
    main()
