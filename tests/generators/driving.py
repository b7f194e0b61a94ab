"""Driving recordings made with NumPy/SciPy alone (not the project's terrain simulator).

A whisker is one or more damped modes, ``x'' + 2ζω x' + ω² x = −g a(t)`` for each mode
(modal participation ``g``), integrated exactly between samples by :func:`scipy.signal.lsim`
at ten times the output rate. The base acceleration ``a`` is white noise through a random
low-pass (a Butterworth of random order and corner, so its spectrum's slope and knee change
from minute to minute) plus a motor tone. The output is averaged over each output sample
(an ADC's conversion window), gets white sensor noise and, optionally, 16-bit codes.
"""

import numpy as np
from scipy.signal import butter, lsim, sosfilt

RATE = 200.0


def drive(
    rng: np.random.Generator,
    f1_hz: float,
    zeta: float,
    *,
    minutes: int = 10,
    seconds: float = 60.0,
    modes: tuple[tuple[float, float, float], ...] = (),
    rate_hz: float = RATE,
    noise: float = 0.02,
    codes: bool = True,
) -> list[tuple[str, np.ndarray]]:
    """``minutes`` recordings of ``seconds`` each, as ``(name, samples)`` pairs.

    Args:
        rng: Random generator.
        f1_hz, zeta: The first mode's frequency (Hz) and damping ratio.
        minutes: Recordings.
        seconds: Length of each (s).
        modes: Further modes as ``(f_hz, zeta, gain)`` (gain relative to the first's).
        rate_hz: Output sample rate (Hz).
        noise: White sensor noise, relative to the signal's standard deviation.
        codes: Round to 16-bit ADC codes (the signal scaled to a standard deviation of
            3000 codes).
    """
    up = 10
    fs = rate_hz * up
    n = round(seconds * fs)
    t = np.arange(n) / fs
    out = []
    for k in range(minutes):
        corner = rng.uniform(0.3, 1.5) * rate_hz / 2
        order = int(rng.integers(1, 4))
        sos = butter(order, min(corner, 0.45 * fs), fs=fs, output="sos")
        acc = sosfilt(sos, rng.standard_normal(n))
        tone = rng.uniform(5, 0.45 * rate_hz)
        acc += 0.1 * np.std(acc) * np.sin(2 * np.pi * tone * t + rng.uniform(0, 6.3))
        x = np.zeros(n)
        for f, z, g in ((f1_hz, zeta, 1.0), *modes):
            w = 2 * np.pi * f
            _, xm, _ = lsim(([-g], [1.0, 2 * z * w, w * w]), acc, t)
            x += xm
        y = x.reshape(-1, up).mean(axis=1)
        y = y / np.std(y)
        y = y + noise * rng.standard_normal(y.size)
        if codes:
            y = np.clip(np.round(3000 * y), -32768, 32767)
        out.append((f"minute-{k}", y))
    return out


def save_csv(folder, signals, rate_hz: float = RATE) -> list:
    """Write each signal to ``folder/<name>.csv`` (columns ``t,adc``); returns the paths."""
    paths = []
    for name, y in signals:
        path = folder / f"{name}.csv"
        t = np.arange(y.size) / rate_hz
        np.savetxt(path, np.column_stack([t, y]), delimiter=",", header="t,adc", comments="",
                   fmt="%.8g")  # fmt: skip
        paths.append(path)
    return paths
