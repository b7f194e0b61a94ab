"""Free decays of one nonlinear mode, integrated by SciPy (``solve_ivp``), not by whiskerid.

    u'' + 2ζ₀ω₀u' + ω₀²(u + κu² + γu³) + c|u'|u' + d u²u' + F sgn(u') = 0

released from rest, read by a Hall sensor at its nominal gain (volts, 1.65 V offset), white
noise at a given SNR and then the ADS1115's code step (±4.096 V range, 125 µV), sampled at
``rate_hz`` from a random instant after the release. Damping laws by their ``ζ(a)`` under
equivalent linearisation (``a`` the amplitude at the sensor): velocity-squared ``c|u'|u'``
adds ``4ca/(3π)`` (∝ a¹), cubic ``d u²u'`` adds ``d a²/(8ω₀)`` (∝ a²), Coulomb ``F sgn u'``
adds ``2F/(πω₀²a)`` (∝ a⁻¹); stiffness ``γu³`` moves ``f`` by ``3γa²/8`` (cubic ±), ``κu²``
by ``−5κ²a²/12`` (quadratic, second order). Each kind below gives the size of its terms at
the release as a ratio (damping: added ``ζ`` over ``ζ₀``; stiffness: relative ``f`` shift).

The integration restarts at every zero of the velocity so that dry friction stays exact
(as ``benchmarks/calibrate_nonlinear.py``'s generator, which has no cubic damping).
"""

import numpy as np
from scipy.integrate import solve_ivp

#: kind → (cubic f shift, quadratic κ·a, velocity-squared ζ ratio, cubic-damping ζ ratio,
#: Coulomb ζ ratio), all at the release amplitude
KINDS = {
    "linear": (0.0, 0.0, 0.0, 0.0, 0.0),
    "cubic+velocity-squared": (-0.004, 0.0, 0.25, 0.0, 0.0),
    "softening+cubic-damping": (-0.004, 0.0, 0.0, 0.5, 0.0),
    "hardening+cubic-damping": (0.004, 0.0, 0.0, 0.5, 0.0),
    "quadratic-stiffness": (0.0, 0.1, 0.0, 0.0, 0.0),
    "coulomb": (0.0, 0.0, 0.0, 0.0, 0.25),
}

#: The ADS1115's code step at its ±4.096 V range (V).
ADS1115_LSB_V = 4.096 / 32768


def integrate(t, f0_hz, zeta0, *, kappa=0.0, gamma=0.0, c=0.0, d=0.0, friction=0.0, u0=1e-3):
    """``u(t)`` (m, at the sensor) of the mode released from rest at ``u0`` at ``t = 0``."""
    w0 = 2 * np.pi * f0_hz

    def rhs(s, y, sgn):
        u, v = y
        spring = w0**2 * (u + kappa * u**2 + gamma * u**3)
        return [v, -(2 * zeta0 * w0 * v + spring + c * abs(v) * v + d * u * u * v
                     + friction * sgn)]  # fmt: skip

    def turn(s, y, sgn):
        return y[1]

    turn.terminal = True
    out = np.zeros(t.size)
    y, s0, sgn = np.array([u0, 0.0]), 0.0, -np.sign(u0)
    while s0 < t[-1]:
        turn.direction = -sgn
        sol = solve_ivp(rhs, (s0, t[-1]), y, args=(sgn,), events=turn, rtol=1e-10,
                        atol=1e-15, method="DOP853", dense_output=True)  # fmt: skip
        sel = (t >= s0) & (t <= sol.t[-1])
        out[sel] = sol.sol(t[sel])[0]
        y, s0 = sol.y[:, -1].copy(), sol.t[-1]
        if sol.status != 1:
            break
        y[1] = 0.0
        if abs(w0**2 * (y[0] + kappa * y[0] ** 2 + gamma * y[0] ** 3)) <= friction:
            out[t > s0] = y[0]  # friction holds it
            break
        sgn = -sgn
    return out


def pluck(kind, seed, *, f0_hz=46.0, rate_hz=200.0, gain_v_per_m=None, snr_db=40.0,
          zeta_range=(0.01, 0.03), amplitude_m=(1e-3, 3e-3)):  # fmt: skip
    """One pluck: ``(t, volts, truth)``; ``truth`` holds ``f0_hz``, ``zeta0`` and the terms'
    coefficients (at the sensor, SI)."""
    shift, ka, zv, zcub, zc = KINDS[kind]
    rng = np.random.default_rng([seed, list(KINDS).index(kind), int(rate_hz)])
    w0 = 2 * np.pi * f0_hz
    zeta0 = float(np.exp(rng.uniform(*np.log(zeta_range))))
    a = float(rng.uniform(*amplitude_m))
    terms = {
        "gamma": shift * 8 / (3 * a**2),
        "kappa": ka / a,
        "c": 3 * np.pi * zv * zeta0 / (4 * a),
        "d": 8 * w0 * zcub * zeta0 / a**2,
        "friction": np.pi * w0**2 * zc * zeta0 * a / 2,
    }
    duration = 4.6 / (w0 * zeta0)
    t = np.arange(0.0, duration, 1 / rate_hz) + rng.uniform(0, 1 / rate_hz)
    u = integrate(t, f0_hz, zeta0, u0=a, **terms)
    gain = 1.0 if gain_v_per_m is None else gain_v_per_m
    v = gain * u
    y = 1.65 + v + rng.normal(0, np.std(v) * 10 ** (-snr_db / 20), v.size)
    y = np.round(y / ADS1115_LSB_V) * ADS1115_LSB_V
    return t, y, {"f0_hz": f0_hz, "zeta0": zeta0, "amplitude_m": a, **terms}
