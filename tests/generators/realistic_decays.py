"""Realistic free-decay recordings, independent of whiskerid's model (NumPy and SciPy only).

A recording as a bench gives it, not as the model predicts it: the beam's first three
bending modes (ratios 1 : 6.27 : 17.55 of an ideal cantilever, each with its own damping),
released from a hand's hold (the hold drifts and trembles at 8–12 Hz, the release leaves
the beam with the hold's deflection and no velocity) or struck by taps at random phases
(several per file, each a velocity impulse at least doubling the motion), plus pink and
white noise, a slow drift, mains hum, and one of two sensors:

* ``"hall"``: a Hall sensor read by an ADS1115 at 200 Hz (displacement; higher modes small
  and aliased), each sample the mean of the signal over the conversion period before it,
  quantised to the converter's step;
* ``"accelerometer"``: about 4 kHz with jittered timestamps and a few gaps of several
  milliseconds (acceleration: the second mode weighted by ω², as strong as the first at
  the start).

Some recordings start after the release (mid-decay) and most end in noise. The truth
(``Truth``) lists the releases a person would mark.

    t, y, truth = recording(np.random.default_rng(seed), "hall")
"""

from dataclasses import dataclass, field

import numpy as np
from scipy import signal

#: Ideal cantilever bending-mode ratios f_k / f_1.
MODE_RATIOS = (1.0, 6.267, 17.55)


@dataclass
class Truth:
    """What made a generated recording."""

    sensor: str
    f1_hz: float
    zeta: float
    releases_s: list[float] = field(default_factory=list)
    from_start: bool = False

    @property
    def n_decays(self) -> int:
        """The decays a person marks."""
        return len(self.releases_s) + int(self.from_start)


def _times(rng, sensor, duration_s):
    if sensor == "hall":
        return np.arange(0.0, duration_s, 1.0 / 200.0)
    dt = 1.0 / 4000.0 * (1.0 + 0.05 * rng.standard_normal(int(duration_s * 4000 * 1.1)))
    dt = np.abs(dt)
    gaps = rng.choice(dt.size, size=3, replace=False)
    dt[gaps] += rng.uniform(0.003, 0.009, size=3)  # the host's scheduling: gaps of a few ms
    t = np.cumsum(dt)
    return t[t < duration_s]


def _modes(rng, sensor, f1, zeta):
    """Frequencies, damping ratios and relative amplitudes (in the sensed quantity)."""
    freqs = np.array(MODE_RATIOS) * f1 * rng.uniform(0.98, 1.02, size=3) ** [0, 1, 1]
    zetas = zeta * np.array([1.0, rng.uniform(0.6, 1.5), rng.uniform(0.6, 1.5)])
    disp = np.array([1.0, rng.uniform(0.01, 0.04), rng.uniform(0.0005, 0.002)])
    amps = disp * (freqs / f1) ** 2 if sensor == "accelerometer" else disp
    return freqs, zetas, amps * rng.choice([-1, 1], size=3)


def _ring(tau, freqs, zetas, amps, phase):
    """Free decay of the modes from ``tau = 0`` (zero before), in the sensed quantity."""
    out = np.zeros_like(tau)
    on = tau >= 0
    for f, z, a in zip(freqs, zetas, amps, strict=True):
        w = 2 * np.pi * f
        out[on] += a * np.exp(-z * w * tau[on]) * np.cos(w * np.sqrt(1 - z * z) * tau[on] + phase)
    return out


def _pink(rng, n):
    white = rng.standard_normal(n)
    b, a = signal.butter(1, 0.002)  # 1/f² below, flat above: a sensor's flicker and wander
    red = signal.lfilter(b, a, white)
    return red / max(np.std(red), 1e-12)


def recording(rng: np.random.Generator, sensor: str = "hall", *, n_taps: int | None = None,
              duration_s: float | None = None) -> tuple[np.ndarray, np.ndarray, Truth]:  # fmt: skip
    """One recording: ``(t, y, truth)``.

    Args:
        rng: Random generator (the recording is a function of its state).
        sensor: ``"hall"`` (200 Hz ADS1115) or ``"accelerometer"`` (~4 kHz, jittered).
        n_taps: Releases/taps in the file (1–4 drawn when None).
        duration_s: Length of the recording (drawn when None).
    """
    hall = sensor == "hall"
    f1 = rng.uniform(8.0, 40.0) if hall else rng.uniform(5.0, 20.0)
    zeta = float(np.exp(rng.uniform(np.log(0.004 if hall else 0.008), np.log(0.04))))
    tau_s = 1.0 / (zeta * 2 * np.pi * f1)  # the first mode's decay time
    n_taps = int(rng.integers(1, 5)) if n_taps is None else n_taps
    # each decay rings for 1.5–4 time constants before the next (the last into noise)
    spacing = rng.uniform(1.5, 4.0, size=n_taps) * tau_s + 30.0 / f1
    lead = rng.uniform(0.3, 1.5)
    if duration_s is None:
        duration_s = min(
            lead + float(np.sum(spacing)) + rng.uniform(0.5, 2.0) * tau_s, 40.0 if hall else 16.0
        )
    t = _times(rng, sensor, duration_s)
    dense = sensor == "hall"
    # the ADS1115 averages over its conversion period before each sample: 8 sub-samples
    tc = (t[:, None] - (1.0 / 250.0) * (np.arange(8) + 0.5) / 8).ravel() if dense else t
    freqs, zetas, amps = _modes(rng, sensor, f1, zeta)
    truth = Truth(sensor=sensor, f1_hz=float(freqs[0]), zeta=zeta)
    x = np.zeros_like(tc)
    from_start = rng.random() < 0.2
    t_next = 0.0 if from_start else lead
    level = 0.0
    for k in range(n_taps):
        if t_next >= duration_s - 10.0 / f1:
            break
        phase = 0.0 if k == 0 else rng.uniform(0, 2 * np.pi)
        # a tap at least doubles the motion: its amplitude against what still rings
        a0 = (
            rng.uniform(0.5, 1.0)
            if k == 0
            else max(level * rng.uniform(2.5, 4.0), rng.uniform(0.4, 1.0))
        )
        if k == 0 and not from_start:
            # the hand's hold before the release: deflection with tremor and a slow sway
            hold = (
                (tc < t_next)
                * a0
                * amps[0]
                * (
                    1.0
                    + 0.01 * np.sin(2 * np.pi * rng.uniform(8, 12) * tc + rng.uniform(0, 6))
                    + 0.02 * np.sin(2 * np.pi * 0.5 * tc)
                )
            )
            if sensor == "accelerometer":
                hold = (tc < t_next) * a0 * 0.01 * np.sin(2 * np.pi * rng.uniform(8, 12) * tc)
            x += hold
        start = -rng.uniform(0.0, 3.0) / f1 if (k == 0 and from_start) else t_next
        x += _ring(tc - start, freqs, zetas, a0 * amps, phase)
        if not (k == 0 and from_start):
            truth.releases_s.append(float(t_next))
        else:
            truth.from_start = True
        t_end = t_next + spacing[k]
        level = a0 * np.exp(-zeta * 2 * np.pi * f1 * (t_end - start))
        t_next = t_end
    if dense:
        x = x.reshape(t.size, 8).mean(axis=1)
    # noise, drift and hum relative to the first mode's largest amplitude (the accelerometer's
    # higher modes spike far above it at a release)
    scale = abs(float(amps[0]))
    noise = rng.uniform(0.005, 0.03) * scale
    y = (
        x
        + noise * rng.standard_normal(t.size)
        + 0.5 * noise * _pink(rng, t.size)
        + rng.uniform(-0.05, 0.05) * scale * t / duration_s  # drift
        + rng.uniform(0.0, 0.02) * scale * np.sin(2 * np.pi * 50.0 * t + rng.uniform(0, 6))
    )
    if sensor == "hall":
        # volts on a ±4.096 V range of 16 bits; the signal spans about ±0.5 V around 1.6 V
        y = 1.6 + 0.5 * y / max(scale, float(np.max(np.abs(y))))
        lsb = 8.192 / 65536
        y = np.clip(np.round(y / lsb) * lsb, -4.096, 4.096 - lsb)
    return t, y, truth
