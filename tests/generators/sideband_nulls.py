"""Seeded recordings with and without sidebands, for calibrating a sideband test.

Independent of the project's model: NumPy only. Each generator takes a
``numpy.random.Generator`` and returns ``(x, carrier_hz)``: the signal sampled at ``fs``
for ``duration_s`` and the carrier a test should look around (``None`` where the recording
has no drive and the test must take the dominant line, as ``whiskerid analyze`` does when
the perturbation frequency is unknown).

**Nulls** (no coherent, phase-coupled pair of lines at ``f_c ± Δ``):

* ``ringing``: a resonance struck at random times (Poisson taps), ringing freely; no drive.
* ``ringing_tone``: the same plus a drive tone away from the resonance.
* ``one_sided``: a carrier and one line at ``f_c + Δ`` only (``side_db`` re carrier).
* ``line_noise``: a carrier in coloured (AR(1), low-pass) noise.
* ``random_am``: a carrier whose amplitude is modulated by Gaussian noise in a 1 Hz band
  centred on ``Δ``: two symmetric *humps* at ``f_c ± Δ``, a continuum, not lines.
* ``phase_jitter``: a carrier whose phase wanders (a random walk), broadening it.

**Positives**: ``am`` (amplitude modulation of depth ``m``: sidebands ``m/2`` of the
carrier's amplitude), ``fm`` (frequency modulation of index ``β``: sidebands ``J₁(β)``),
``asymmetric`` (two side lines of unequal amplitude, phase-coupled to the carrier as
modulation would make them).

``placement``: ``"on"`` puts ``f_c`` and ``Δ`` on the bins of a 4 s Welch segment
(multiples of 0.25 Hz, the analyze default), ``"half"`` puts ``Δ`` half-way between them.
``snr_db``: the carrier's power over the white noise's (per sample).
"""

import numpy as np

FS = 200.0
BIN_HZ = 0.25  # bins of analyze's default 4 s Welch segment

NULL_KINDS = ("ringing", "ringing_tone", "one_sided", "one_sided_weak", "line_noise",
              "random_am", "random_am_low", "phase_jitter")  # fmt: skip
POSITIVE_KINDS = ("am", "fm", "asymmetric")


def _t(duration_s, fs):
    return np.arange(round(duration_s * fs)) / fs


def _noise(rng, n, snr_db, amp=1.0):
    return amp / np.sqrt(2) * 10 ** (-snr_db / 20) * rng.standard_normal(n)


def _carrier_hz(rng, placement="on"):
    """A carrier on a bin between 20 and 40 Hz."""
    return BIN_HZ * rng.integers(80, 160)


def _delta_hz(rng, placement="on", lo=2.0, hi=8.0):
    d = BIN_HZ * rng.integers(round(lo / BIN_HZ), round(hi / BIN_HZ))
    return d + (BIN_HZ / 2 if placement == "half" else 0.0)


def _band_noise(rng, n, fs, lo_hz, hi_hz):
    """Unit-RMS Gaussian noise with a flat spectrum between ``lo_hz`` and ``hi_hz``."""
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1 / fs)
    spec[(f < lo_hz) | (f > hi_hz)] = 0
    y = np.fft.irfft(spec, n)
    return y / np.std(y)


def ringing(rng, duration_s=20.0, fs=FS, rate_per_s=3.0, tone=False, snr_db=30.0):
    """Free ringing at a resonance ``f1`` (25–60 Hz, ζ 0.02–0.06) struck at random."""
    t = _t(duration_s, fs)
    f1, zeta = rng.uniform(25, 60), rng.uniform(0.02, 0.06)
    wd = 2 * np.pi * f1 * np.sqrt(1 - zeta**2)
    # impulse response convolved with a Poisson train of random-amplitude taps
    h_t = np.arange(round(min(8 / (zeta * 2 * np.pi * f1), duration_s) * fs)) / fs
    h = np.exp(-zeta * 2 * np.pi * f1 * h_t) * np.sin(wd * h_t)
    taps = np.zeros(t.size)
    k = rng.poisson(rate_per_s * duration_s)
    taps[rng.integers(0, t.size, k)] += rng.standard_normal(k)
    x = np.convolve(taps, h)[: t.size]
    x = x / np.std(x)
    carrier = None
    if tone:
        carrier = _carrier_hz(rng)
        while abs(carrier - f1) < 5:
            carrier = _carrier_hz(rng)
        x = x + np.sqrt(2) * np.sin(2 * np.pi * carrier * t + rng.uniform(0, 2 * np.pi))
    return x + _noise(rng, t.size, snr_db), carrier


def one_sided(rng, duration_s=20.0, fs=FS, side_db=-10.0, snr_db=30.0, placement="on"):
    """A carrier and one line at ``f_c ± Δ`` (which side at random)."""
    t = _t(duration_s, fs)
    fc, d = _carrier_hz(rng), _delta_hz(rng, placement)
    side = fc + d * rng.choice([-1, 1])
    x = np.sin(2 * np.pi * fc * t) + 10 ** (side_db / 20) * np.sin(
        2 * np.pi * side * t + rng.uniform(0, 2 * np.pi)
    )
    return x + _noise(rng, t.size, snr_db), fc


def line_noise(rng, duration_s=20.0, fs=FS, snr_db=20.0):
    """A carrier in AR(1) noise (pole 0.6–0.95: red, a floor falling with frequency)."""
    t = _t(duration_s, fs)
    fc = _carrier_hz(rng)
    a = rng.uniform(0.6, 0.95)
    w = _noise(rng, t.size, snr_db)
    y = np.empty_like(w)
    acc = 0.0
    for i, wi in enumerate(w):
        acc = a * acc + wi
        y[i] = acc
    y = y * np.sqrt(1 - a**2)  # the same variance as the white noise
    return np.sin(2 * np.pi * fc * t + rng.uniform(0, 2 * np.pi)) + y, fc


def random_am(rng, duration_s=20.0, fs=FS, depth=0.3, band_hz=1.0, centre_hz=None,
              snr_db=30.0):  # fmt: skip
    """A carrier amplitude-modulated by Gaussian noise in a ``band_hz`` band centred on
    ``centre_hz`` (2–8 Hz by default; ``0`` for a low-pass band ``0–band_hz``)."""
    t = _t(duration_s, fs)
    fc = _carrier_hz(rng)
    c = rng.uniform(2.0, 8.0) if centre_hz is None else centre_hz
    lo, hi = max(c - band_hz / 2, 0.0), (c + band_hz / 2 if c > 0 else band_hz)
    a = _band_noise(rng, t.size, fs, lo, hi)
    x = (1 + depth * a) * np.sin(2 * np.pi * fc * t + rng.uniform(0, 2 * np.pi))
    return x + _noise(rng, t.size, snr_db), fc


def phase_jitter(rng, duration_s=20.0, fs=FS, linewidth_hz=0.05, snr_db=30.0):
    """A carrier whose phase is a random walk (Lorentzian line of half-width
    ``linewidth_hz``)."""
    t = _t(duration_s, fs)
    fc = _carrier_hz(rng)
    phi = np.cumsum(np.sqrt(4 * np.pi * linewidth_hz / fs) * rng.standard_normal(t.size))
    return np.sin(2 * np.pi * fc * t + phi) + _noise(rng, t.size, snr_db), fc


def am(rng, duration_s=20.0, fs=FS, depth=0.3, snr_db=40.0, placement="on", delta_hz=None):
    """Amplitude modulation ``(1 + m cos(2πΔt + φ)) sin(2πf_c t)``."""
    t = _t(duration_s, fs)
    fc = _carrier_hz(rng)
    d = _delta_hz(rng, placement) if delta_hz is None else delta_hz
    x = (1 + depth * np.cos(2 * np.pi * d * t + rng.uniform(0, 2 * np.pi))) * np.sin(
        2 * np.pi * fc * t
    )
    return x + _noise(rng, t.size, snr_db), fc


def fm(rng, duration_s=20.0, fs=FS, beta=0.3, snr_db=40.0, placement="on"):
    """Frequency modulation ``sin(2πf_c t + β sin(2πΔt + φ))``."""
    t = _t(duration_s, fs)
    fc, d = _carrier_hz(rng), _delta_hz(rng, placement)
    x = np.sin(2 * np.pi * fc * t + beta * np.sin(2 * np.pi * d * t + rng.uniform(0, 6.3)))
    return x + _noise(rng, t.size, snr_db), fc


def asymmetric(rng, duration_s=20.0, fs=FS, depth=0.3, ratio_db=-6.0, snr_db=40.0,
               placement="on"):  # fmt: skip
    """Two side lines at ``f_c ± Δ``, the upper one ``depth/2`` of the carrier, the lower
    ``ratio_db`` below it (modulation of amplitude and phase together)."""
    t = _t(duration_s, fs)
    fc, d = _carrier_hz(rng), _delta_hz(rng, placement)
    ph = rng.uniform(0, 2 * np.pi)
    hi = depth / 2 * np.sin(2 * np.pi * (fc + d) * t + ph)
    lo = depth / 2 * 10 ** (ratio_db / 20) * np.sin(2 * np.pi * (fc - d) * t - ph)
    return np.sin(2 * np.pi * fc * t) + hi + lo + _noise(rng, t.size, snr_db), fc


def null(kind: str, rng, duration_s=20.0, fs=FS):
    """One recording of a null kind (see the module docstring)."""
    if kind == "ringing":
        return ringing(rng, duration_s, fs)
    if kind == "ringing_tone":
        return ringing(rng, duration_s, fs, tone=True)
    if kind == "one_sided":
        return one_sided(rng, duration_s, fs, side_db=-10.0)
    if kind == "one_sided_weak":
        return one_sided(rng, duration_s, fs, side_db=-52.0)
    if kind == "line_noise":
        return line_noise(rng, duration_s, fs)
    if kind == "random_am":
        return random_am(rng, duration_s, fs)
    if kind == "random_am_low":
        return random_am(rng, duration_s, fs, centre_hz=0.0)
    if kind == "phase_jitter":
        return phase_jitter(rng, duration_s, fs)
    raise ValueError(f"unknown null kind {kind!r}")


def positive(kind: str, rng, duration_s=20.0, fs=FS, *, depth=0.3, snr_db=40.0,
             placement="on"):  # fmt: skip
    """One recording with sidebands: ``am``, ``fm`` (index ``depth``) or ``asymmetric``."""
    if kind == "am":
        return am(rng, duration_s, fs, depth, snr_db, placement)
    if kind == "fm":
        return fm(rng, duration_s, fs, depth, snr_db, placement)
    if kind == "asymmetric":
        return asymmetric(rng, duration_s, fs, depth, snr_db=snr_db, placement=placement)
    raise ValueError(f"unknown positive kind {kind!r}")
