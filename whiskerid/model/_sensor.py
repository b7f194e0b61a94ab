"""Hall sensor and ADS1115 models: from beam deflection to what a Raspberry Pi records.

The chain is: relative deflection ``w(x_s, t)`` (m) → Hall voltage
``V = V₀ + g w + g₂ w²`` (V) → ADS1115 conversion: the delta-sigma converter averages its
input over one conversion period ``1/DR`` (a first-order sinc response
``|sinc(f/DR)|``), adds input-referred noise, clips to the PGA full-scale range and rounds to
16-bit two's-complement codes (``LSB = FSR/32768``). The Pi samples in single-shot mode on
its own schedule (200 Hz nominal) and timestamps every sample, so sample times carry jitter
and the conversion period carries the oscillator error (±10 % on a real chip).
"""

from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Codes, Samples, Scalar, Times
from ..io import _ads1115_spec as spec


def _scalar(x) -> jax.Array:
    return jnp.asarray(x, dtype=float)


class HallSensor(eqx.Module):
    """Linear Hall sensor plus amplifier, with an optional quadratic term (a pytree).

    Attributes:
        gain_v_per_m: Output change per metre of relative deflection (V/m), amplifier included.
        offset_v: Output at zero deflection (V).
        quadratic_v_per_m2: Second-order term (V/m²): the field of a small magnet is not
            linear in its displacement.
    """

    gain_v_per_m: Scalar = eqx.field(converter=_scalar, default=2000.0)
    offset_v: Scalar = eqx.field(converter=_scalar, default=1.65)
    quadratic_v_per_m2: Scalar = eqx.field(converter=_scalar, default=0.0)

    def voltage(self, deflection_m):
        """Sensor output (V) for a relative deflection (m)."""
        w = jnp.asarray(deflection_m)
        return self.offset_v + self.gain_v_per_m * w + self.quadratic_v_per_m2 * w**2


@dataclass(frozen=True)
class ADS1115Model:
    """Signal-level model of an ADS1115 sampled by a host on its own schedule.

    Attributes:
        fsr_v: PGA full-scale range (V): 6.144, 4.096, 2.048, 1.024, 0.512 or 0.256.
        data_rate_sps: Nominal conversion rate: 8, 16, 32, 64, 128, 250, 475 or 860 SPS.
        clock_error: Fractional oscillator error; ``+0.05`` makes conversions 5 % shorter.
        noise_v_rms: Input-referred noise per conversion (V RMS).
        jitter_s: Standard deviation of the host's sampling instants around its schedule (s).
        averaging_points: Points used to average the input across one conversion period.
    """

    fsr_v: float = 4.096
    data_rate_sps: int = 475
    clock_error: float = 0.0
    noise_v_rms: float = 0.0
    jitter_s: float = 0.0
    averaging_points: int = 16

    def __post_init__(self):
        spec.check_fsr(self.fsr_v)
        spec.check_data_rate(self.data_rate_sps)
        if not -spec.OSCILLATOR_TOLERANCE * 2 < self.clock_error < spec.OSCILLATOR_TOLERANCE * 2:
            raise ValueError(
                f"clock_error = {self.clock_error!r} is not a plausible fraction "
                "(the datasheet gives +-0.10)"
            )
        if self.noise_v_rms < 0 or self.jitter_s < 0:
            raise ValueError("noise_v_rms and jitter_s must be zero or positive")
        if self.averaging_points < 1:
            raise ValueError("averaging_points must be at least 1")

    @property
    def lsb_v(self) -> float:
        """Volts per code (``FSR/32768``)."""
        return spec.lsb_volts(self.fsr_v)

    @property
    def conversion_time_s(self) -> float:
        """Actual conversion period, oscillator error included (s)."""
        return 1.0 / (self.data_rate_sps * (1.0 + self.clock_error))

    def averaging_offsets(self) -> jax.Array:
        """Times before each sample instant at which the input is averaged (midpoint rule)."""
        k = jnp.arange(self.averaging_points)
        return -(k + 0.5) / self.averaging_points * self.conversion_time_s

    def average(self, signal_fn, t: Times) -> Samples:
        """Average of ``signal_fn`` over the conversion period ending at each ``t`` (JAX)."""
        tt = jnp.asarray(t)[:, None] + self.averaging_offsets()[None, :]
        return jnp.mean(signal_fn(tt.reshape(-1)).reshape(tt.shape), axis=1)

    def quantise(self, volts: Samples) -> Codes:
        """Clip to the full-scale range and round to 16-bit two's-complement codes."""
        codes = jnp.round(jnp.asarray(volts) / self.lsb_v)
        return jnp.clip(codes, spec.CODE_MIN, spec.CODE_MAX).astype(jnp.int32)

    def codes_to_volts(self, codes) -> Samples:
        """Exact PGA scaling of output codes (V)."""
        return jnp.asarray(codes, dtype=float) * self.lsb_v

    def convert(self, signal_fn, t: Times, *, rng: np.random.Generator | None = None) -> Codes:
        """Codes a host would read at instants ``t`` for an input voltage ``signal_fn(t)``.

        Args:
            signal_fn: Vectorised function of time (s) giving the input voltage (V).
            t: Instants at which conversions complete (s).
            rng: Source of the conversion noise (needed when ``noise_v_rms > 0``).
        """
        volts = self.average(signal_fn, t)
        if self.noise_v_rms > 0:
            if rng is None:
                raise ValueError("convert() needs rng when noise_v_rms > 0")
            volts = volts + self.noise_v_rms * rng.standard_normal(np.shape(volts))
        return self.quantise(volts)

    def sample_times(
        self, rate_hz: float, duration_s: float, *, rng: np.random.Generator | None = None
    ) -> np.ndarray:
        """Instants at which a host polling at ``rate_hz`` gets its samples (s, increasing).

        The first sample completes one conversion after the start, so every averaging window
        lies at ``t ≥ 0``.
        """
        n = round(duration_s * rate_hz)
        t = self.conversion_time_s + np.arange(n) / rate_hz
        if self.jitter_s > 0:
            if rng is None:
                raise ValueError("sample_times() needs rng when jitter_s > 0")
            # Clipped so that jitter never reorders samples.
            jitter = np.clip(
                rng.standard_normal(n) * self.jitter_s, -0.45 / rate_hz, 0.45 / rate_hz
            )
            t = t + jitter
        return t
