"""The whisker's own transfer function, for features that do not depend on the whisker.

A whisker turns the base motion into a signal through its resonances: the Hall sensor reads
the relative deflection at the sensor position (modes, damping and the static correction of
the exact model), the ADS1115 averages it over a conversion, and the host's sample rate folds
whatever lies above Nyquist back into the band. A recording in codes is therefore, bin by bin,

    X(f) = T(f) B(f),    T(f) = G M diag(H_p(f)),

with ``B`` the base acceleration in each bending plane (m/s²), ``H_p`` the deflection per unit
base acceleration of plane ``p`` times the conversion's averaging response, ``M`` the sensors'
cross-talk and ``G`` their gains in codes per metre. :class:`WhiskerResponse` computes ``T``
from a whisker record (and its ``[planes]`` table for two sensors) and gives two filters:

* ``to_base = T⁻¹`` (regularised where the whisker hardly moves): an estimate of the base
  motion itself, what the ground did, from which band levels in dB are read;
* ``recolour = T_ref T⁻¹``: the window as the reference whisker (the one a model was trained
  with) would have recorded the same base motion. With the training whisker itself this is
  the identity, so a model trained on one whisker and run on another sees the windows it
  knows.

Aliasing is accounted for in the magnitude: the effective gain of a bin at ``f`` is
``√(Σ_m |H(f_m)|² (f/f_m)^α)`` over its aliases ``f_m`` (``f`` itself included), with the
phase of the bin's own frequency: the base acceleration's power is taken to fall as
``f^−α`` across the aliases (``alias_slope``). With ``α = 0`` (flat) a whisker whose second
mode folds into the band is credited with all of that mode's gain, as if the ground shook
as hard at 200–400 Hz as in the band; the wheels filter the ground's profile, and base
acceleration falls above the band (on the simulated terrains by 1–14 dB from 80 to 280 Hz),
so the flat model makes such a whisker read its folded mode's bins too loud when recoloured
to, and too quiet when divided out.
"""

import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..model import WhiskerRecord, harmonic_steady_state, load_record, observe
from ..terrain import SensorPlanes

#: Aliases of a bin summed on each side (the ADS1115's averaging nulls the rest).
ALIASES = 4
#: Whiskers a model with a matched noise floor serves: first natural frequency within these
#: factors of the training whisker's, damping within these factors of its ζ.
F1_SPAN = (0.6, 1.6)
ZETA_SPAN = (0.5, 2.0)
#: ``α`` of the aliases' weight ``(f/f_m)^α`` in models that weight them (see the module
#: docstring): base acceleration power falling as ``1/f`` above the band.
ALIAS_SLOPE = 1.0
#: Whiskers of that span each training window of a whisker-aware model is also seen
#: through (:meth:`WhiskerResponse.span`, :func:`whiskerid.train_classifier`).
SPAN_WHISKERS = 8
#: Regularisation of the inverse, relative to the largest gain: bins where the whisker's
#: response is this far below its peak are not amplified further.
REGULARISATION = 1e-3


def deflection_per_acc(whisker, freqs_hz) -> np.ndarray:
    """Complex relative deflection at the sensor per unit base acceleration (m per m/s²).

    From the exact model's harmonic steady state (static correction included): the response
    to ``y_b = sin(ω t)/ω²`` read at ``t = 0`` and a quarter period later. Compiled once
    per number of frequencies; the whisker is traced.
    """
    f = jnp.maximum(jnp.asarray(freqs_hz, dtype=float), 1e-3)
    return np.asarray(_deflection_per_acc(whisker, f))


@eqx.filter_jit
def _deflection_per_acc(whisker, f):
    def one(fb):
        w = 2 * jnp.pi * fb
        t = jnp.stack([0.0, 0.25 / fb])
        d = observe(whisker, harmonic_steady_state(whisker, t, fb_hz=fb, hb_m=1.0 / w**2))
        # base acceleration −sin(ωt): phasor −1; deflection phasor d(T/4) + i d(0)
        return -(d[1] + 1j * d[0])

    return jax.vmap(one)(f)


def averaging_response(freqs_hz, conversion_s: float, points: int) -> np.ndarray:
    """The ADS1115's mean over a conversion ending at the sample, as a complex gain."""
    tau = (np.arange(points) + 0.5) / points * conversion_s
    return np.mean(np.exp(-2j * np.pi * np.outer(freqs_hz, tau)), axis=1)


@dataclass(frozen=True)
class WhiskerResponse:
    """A calibrated whisker and its sensors as seen at one sample rate.

    Attributes:
        record: The whisker record (its ``[planes]`` table for two sensors).
        amplifier: Gain of the sensors' amplifier on top of the record's Hall gain.
        channels: 1 (sensor A, vertical plane) or 2 (A vertical, B lateral).
        alias_slope: ``α``: the aliases of a bin at ``f`` count with weight ``(f/f_m)^α``
            (the base acceleration's power falling as ``f^−α``); 0, flat, by default
            (models written before the weight existed). A model's feature settings set it
            (:attr:`FeatureSpec.alias_slope`).
    """

    record: WhiskerRecord
    amplifier: float = 1.0
    channels: int = 1
    alias_slope: float = 0.0

    def __post_init__(self):
        if self.channels not in (1, 2):
            raise ValueError(
                f"a whisker has one or two Hall sensors; these windows have {self.channels} "
                "channels"
            )
        if not (np.isfinite(self.amplifier) and self.amplifier > 0):
            raise ValueError(f"amplifier {self.amplifier!r} must be a positive number")
        if not (np.isfinite(self.alias_slope) and self.alias_slope >= 0):
            raise ValueError(f"alias_slope {self.alias_slope!r} must be a number ≥ 0")

    def transfer(self, freqs_hz, rate_hz: float) -> np.ndarray:
        """``T(f)`` in codes per m/s², shape ``(bins, channels, channels)`` (aliasing in the
        magnitude, see the module docstring)."""
        planes = SensorPlanes.from_record(self.record)
        whiskers = planes.whiskers(self.record)[: self.channels]
        halls = planes.halls(self.record, self.amplifier)[: self.channels]
        adc = self.record.adc
        f = np.asarray(freqs_hz, dtype=float)
        # every alias of every bin in one call: row m is f + m·rate (m = −A … A), row A
        # the bins' own frequencies
        fm = np.abs(f[None, :] + np.arange(-ALIASES, ALIASES + 1)[:, None] * rate_hz)
        avg = averaging_response(fm.ravel(), adc.conversion_time_s, adc.averaging_points)
        weight = (np.maximum(f, 1e-3)[None, :] / np.maximum(fm, 1e-3)) ** self.alias_slope
        per_plane = []
        for w in whiskers:
            h = (deflection_per_acc(w, fm.ravel()) * avg).reshape(fm.shape)
            power = np.sum(np.abs(h) ** 2 * weight, axis=0)
            per_plane.append(np.sqrt(power) * np.exp(1j * np.angle(h[ALIASES])))
        gains = np.array([float(h.gain_v_per_m) for h in halls]) / adc.lsb_v
        mix = planes.mixing()[: self.channels, : self.channels]
        return (gains[:, None] * mix)[None] * np.stack(per_plane, axis=1)[:, None, :]

    def to_base(self, freqs_hz, rate_hz: float) -> np.ndarray:
        """Regularised ``T⁻¹`` (m/s² per code), shape ``(bins, channels, channels)``."""
        t = self.transfer(freqs_hz, rate_hz)
        lam = REGULARISATION * np.max(np.abs(t))
        th = np.conj(np.swapaxes(t, 1, 2))
        eye = np.eye(self.channels)[None]
        return np.linalg.solve(th @ t + lam**2 * eye, th)

    def scaled(self, f1_factor: float, zeta_factor: float) -> "WhiskerResponse":
        """This whisker with its natural frequencies times ``f1_factor`` (stiffness times
        its square) and its damping times ``zeta_factor``, in both planes."""
        rec = self.record
        s = rec.structure
        k = f1_factor**2
        stiffer = (replace(s, shear_modulus_pa=s.shear_modulus_pa * k) if s.kind == "coil"
                   else replace(s, youngs_modulus_pa=s.youngs_modulus_pa * k))  # fmt: skip
        zeta = np.minimum(np.asarray(rec.zeta, dtype=float) * zeta_factor, 0.9)
        planes = SensorPlanes.from_record(rec)
        extra = dict(rec.extra)
        if planes.lateral_zeta is not None:
            lat = np.minimum(np.asarray(planes.lateral_zeta, dtype=float) * zeta_factor, 0.9)
            extra["planes"] = {**planes.to_table(), "lateral_zeta": lat.tolist()}
        zeta_v = float(zeta) if zeta.ndim == 0 else tuple(float(z) for z in zeta)
        return replace(self, record=rec.replace(structure=stiffer, zeta=zeta_v, extra=extra))

    def span(self, count: int, seed: int = 0) -> list["WhiskerResponse"]:
        """``count`` whiskers spread over the span a model trained with this one serves
        (f₁ × :data:`F1_SPAN`, ζ × :data:`ZETA_SPAN`): log-uniform in both, one in each
        ``1/count`` slice of either range (a Latin hypercube), seeded."""
        rng = np.random.default_rng(seed)

        def spread(lo_hi):
            lo, hi = np.log(lo_hi)
            u = (rng.permutation(count) + rng.uniform(size=count)) / count
            return np.exp(lo + u * (hi - lo))

        f1, zeta = spread(F1_SPAN), spread(ZETA_SPAN)
        return [self.scaled(float(a), float(b)) for a, b in zip(f1, zeta, strict=True)]

    def rerecord(self, other: "WhiskerResponse", freqs_hz, rate_hz: float
                 ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """What turns a recording of this whisker into one of ``other``'s of the same base
        motion: the filter ``T_other T⁻¹`` (shape ``(bins, channels, channels)``), and per
        bin and channel the white floor to add, ``√(max(1 − |T_other / T|², 0))`` times the
        recording's own (shape ``(bins, channels)``). The sensors' floor (ADC noise,
        quantisation, the error of timestamp jitter) is white in codes: it never passed
        through the whisker's response. Where ``other`` responds more weakly, the filter
        lowers this recording's floor below what ``other``'s sensors would have added, and
        the noise makes it up."""
        t_self = np.abs(np.diagonal(self.transfer(freqs_hz, rate_hz), axis1=1, axis2=2))
        t_other = np.abs(np.diagonal(other.transfer(freqs_hz, rate_hz), axis1=1, axis2=2))
        ratio = t_other / np.maximum(t_self, 1e-300)
        return self.recolour(other, freqs_hz, rate_hz), np.sqrt(np.maximum(1 - ratio**2, 0.0))

    def floor_gain(self, freqs_hz, rate_hz: float) -> np.ndarray:
        """``G(f)``: per channel, how far the whiskers of a span around this one
        (:data:`F1_SPAN` × :data:`ZETA_SPAN`, a 9 × 3 grid) fall below it on average,
        ``√(mean |T_self / T_other|²)`` (at least 1), shape ``(bins, channels)``.

        Recoloured to this whisker, a recording of a weaker one has its noise floor (ADC
        noise, quantisation, the error of timestamp jitter) raised by ``|T_self/T_other|``;
        a model that sees every window with its floor raised to ``G`` times its own sees
        one floor for every whisker up to the span's average, and a floor not far below
        that of a weaker one. (Raising it to the span's weakest drowned too much of what
        the windows hold: every whisker, the training one included, did worse.)
        """
        own = np.abs(np.diagonal(self.transfer(freqs_hz, rate_hz), axis1=1, axis2=2))
        ratios = []
        for f1 in np.geomspace(*F1_SPAN, 9):
            for z in (ZETA_SPAN[0], 1.0, ZETA_SPAN[1]):
                other = self.scaled(float(f1), z).transfer(freqs_hz, rate_hz)
                ratio = own / np.maximum(np.abs(np.diagonal(other, axis1=1, axis2=2)), 1e-300)
                ratios.append(ratio**2)
        return np.sqrt(np.maximum(np.mean(ratios, axis=0), 1.0))

    def dither(self, reference: "WhiskerResponse", freqs_hz, rate_hz: float) -> np.ndarray:
        """Shape of the noise that brings this whisker's floor, recoloured to
        ``reference``, up to ``reference``'s matched floor: ``√(max(G² − g², 0))`` with
        ``g = |T_ref / T_self|`` and ``G`` :meth:`floor_gain` of the reference, per bin
        and channel (times the window's own floor, see the features)."""
        t_ref = np.abs(np.diagonal(reference.transfer(freqs_hz, rate_hz), axis1=1, axis2=2))
        t_own = np.abs(np.diagonal(self.transfer(freqs_hz, rate_hz), axis1=1, axis2=2))
        g = t_ref / np.maximum(t_own, 1e-300)
        big = reference.floor_gain(freqs_hz, rate_hz)
        return np.sqrt(np.maximum(big**2 - g**2, 0.0))

    def recolour(self, reference: "WhiskerResponse", freqs_hz, rate_hz: float) -> np.ndarray:
        """``T_ref T⁻¹``: the windows as the ``reference`` whisker would have recorded them."""
        return reference.transfer(freqs_hz, rate_hz) @ self.to_base(freqs_hz, rate_hz)

    def to_dict(self) -> dict:
        """JSON-able form (model files): the record as TOML text, and the amplifier."""
        return {"name": self.record.name, "toml": self.record.to_toml(),
                "amplifier": self.amplifier}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict, channels: int) -> "WhiskerResponse":
        """Inverse of :meth:`to_dict`.

        Raises:
            RecordError: The record in ``d`` does not load.
        """
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "whisker.toml"
            path.write_text(str(d["toml"]))
            record = load_record(path)
        return cls(record, float(d.get("amplifier", 1.0)), channels)
