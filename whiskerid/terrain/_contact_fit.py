"""Contact parameters fitted to one Hall signal, through the contact simulator.

One sensor at the whisker's base cannot separate what the ground's profile does from what
the contact does, sample by sample: the profile under the tip is unknown. So the profile is
treated as a random process and the fit matches *statistics* that do not need it.

Model (the "statistical twin" of a recording)
---------------------------------------------
* The ground under the tip is a Gaussian process with the ISO 8608 form of spatial spectrum,
  ``G(n) = (ρ²/n₀) (n/n₀)^(−w)`` (m³; ``n`` in cycles/m, ``n₀ = 10`` cycles/m), seen at the
  recording's speed ``v`` as the temporal spectrum ``S(f) = G(f/v)/v`` between 0.5 and
  400 Hz. ``ρ`` (m, the roughness: the RMS height per unit ln-band at 10 cycles/m) and
  ``w`` (the slope) are fitted.
* The tip rests on it with a linear penalty spring of stiffness ``k`` in series with a
  fixed ``K_CAP`` (the tip's own compliance caps what a 200 Hz signal can tell apart and
  keeps the fixed-step integration stable), preload ``d₀`` and Coulomb friction ``μ``
  (Hunt–Crossley damping set by a fixed damping ratio ``CONTACT_ZETA`` at the static
  load), integrated by :func:`simulate_contact`
  with the whisker's first two modes on a fixed 2 kHz grid. The body's own motion is left
  out: its heave is slow, and what the tip does relative to the base is what the ground's
  process stands for.
* The Hall sensor's voltage at 200 Hz plus the ADC's noise and quantisation, cut into 1 s
  windows; per window: the mean deflection (the static contact force: the whisker's
  calibration gives the zero), the log power in seven bands (1–100 Hz), the skewness and
  the asymmetry of the 5–50–95 % quantiles (the tip losing the ground clips one side).
* Expected statistics: the mean over ``draws`` profile draws whose random numbers are fixed
  (common random numbers: the objective is smooth in the parameters).

Fit: Levenberg–Marquardt (optimistix) on the statistics whitened by their covariance over
the recording's windows (times ``1/n_obs + 1/n_sim``, the simulated mean's own noise
included), with weak log-normal priors that keep degenerate directions finite; derivatives
in forward mode through diffrax. The covariance of the estimate is the inverse of
``JᵀJ`` at the solution; :attr:`ContactFit.correlation` shows what is degenerate (the
static force depends on ``d₀ (cos θ + μ sin|θ|)`` and, for grounds much stiffer than the
whisker's tip, not on ``k``).
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..model import HallSensor, WhiskerRecord, paper_record
from ._contact import ContactInputs, ContactModes, ContactParams, contact_modes, simulate_contact
from ._contact_runs import DEFAULT_TILT_RAD
from ._sensor import amplified_hall

PARAM_NAMES = ("ln_stiffness", "ln_preload", "ln_friction", "ln_roughness", "slope")
#: Prior centre and width per parameter (ln N/m, ln m, ln 1, ln m, 1): weak, to keep
#: degenerate directions finite.
PRIOR_MEAN = np.array([np.log(300.0), np.log(1e-3), np.log(0.6), np.log(1e-4), 2.0])
PRIOR_SD = np.array([2.5, 1.0, 0.5, 2.5, 1.0])
STAT_NAMES = ("mean", "lnP_1_3", "lnP_3_8", "lnP_8_16", "lnP_16_30", "lnP_30_45", "lnP_45_60",
              "lnP_60_100", "skewness", "quantile_asymmetry")  # fmt: skip
BANDS_HZ = ((1, 3), (3, 8), (8, 16), (16, 30), (30, 45), (45, 60), (60, 100))
K_CAP = 5e3  # N/m, in series with the fitted k
#: Damping ratio of the tip on the ground at the static load (not fitted): the
#: Hunt–Crossley α follows as ``2 ζ_c √(m k)/(k δ_s)``, so that the contact's damping stays
#: within what fixed 0.5 ms steps integrate stably (a fixed α = 20 s/m on a stiff ground
#: would need steps ten times shorter)
CONTACT_ZETA = 0.2
#: m/s: the friction's regularisation, wider than the simulator's 1 cm/s (at 0.1 m/s the
#: tip still slides at 0.997 μN): the steep stick branch would need shorter fixed steps
SLIP = 0.03
N0 = 10.0  # cycles/m, the roughness' reference spatial frequency
GRID_HZ = 2000.0
RATE_HZ = 200.0
WINDOW = 200
SETTLE_S = 0.5


def window_stats(x: jax.Array) -> jax.Array:
    """Statistics of each window of a deflection signal (µm), shape ``(windows, stats)``.

    Args:
        x: Samples at 200 Hz, shape ``(windows, 200)``.
    """
    mean = jnp.mean(x, axis=1)
    d = x - mean[:, None]
    hann = jnp.hanning(WINDOW + 2)[1:-1]
    power = jnp.abs(jnp.fft.rfft(d * hann, axis=1)) ** 2
    f = np.fft.rfftfreq(WINDOW, 1 / RATE_HZ)
    bands = [jnp.log(jnp.mean(power[:, (f >= lo) & (f < hi)], axis=1)) for lo, hi in BANDS_HZ]
    sd = jnp.sqrt(jnp.mean(d**2, axis=1))
    skew = jnp.mean(d**3, axis=1) / sd**3
    q05, q50, q95 = (jnp.percentile(x, q, axis=1) for q in (5, 50, 95))
    asym = jnp.log((q95 - q50) / (q50 - q05))
    return jnp.stack([mean, *bands, skew, asym], axis=1)


_window_stats = jax.jit(window_stats)  # one compilation, not one per operation


def recording_stats(volts, hall: HallSensor, *, block: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Mean statistics of a 200 Hz Hall recording and the covariance per window.

    Consecutive windows share the profile's long wavelengths, so their statistics are
    correlated: the covariance of one window's statistics is inflated, statistic by
    statistic, by the ratio of the variance of means of ``block`` consecutive windows to
    what independent windows would give (at least 1), so that dividing it by the number of
    windows gives the variance of the mean.

    Returns:
        ``(mean, cov)``: shapes ``(stats,)`` and ``(stats, stats)``.
    """
    v = np.asarray(volts, dtype=float)
    n = v.size // WINDOW
    if n < 2 * block:
        raise ValueError(
            f"{v.size} samples make {n} windows of {WINDOW}; need at least {2 * block}"
        )
    x = _to_um(v[: n * WINDOW].reshape(n, WINDOW), hall)
    s = np.asarray(_window_stats(jnp.asarray(x)))
    cov = np.cov(s, rowvar=False)
    nb = n // block
    means = s[: nb * block].reshape(nb, block, -1).mean(axis=1)
    ratio = np.maximum(np.var(means, axis=0, ddof=1) * block / np.diag(cov), 1.0)
    return s.mean(axis=0), cov * np.sqrt(np.outer(ratio, ratio))


def _to_um(volts, hall: HallSensor):
    """Deflection at the sensor (µm) from volts (linear part of the Hall sensor)."""
    return (volts - hall.offset_v) / hall.gain_v_per_m * 1e6


def _first_modes(modes: ContactModes, keep: int) -> ContactModes:
    """The first ``keep`` modes, the truncated ones' static tip-force response kept."""
    drop = slice(keep, None)
    extra = jnp.sum(modes.phi_sensor[drop] * modes.phi_tip[drop]
                    / (modes.modal_mass[drop] * modes.omega[drop] ** 2))  # fmt: skip
    return ContactModes(modes.omega[:keep], modes.zeta[:keep], modes.gamma[:keep],
                        modes.phi_tip[:keep], modes.phi_sensor[:keep],
                        modes.modal_mass[:keep], modes.residual_acc,
                        modes.residual_force + extra)  # fmt: skip


class ContactTwin(eqx.Module):
    """The statistical twin: whisker, sensor, speed and the fixed random numbers.

    Attributes:
        modes: The whisker's first two modes.
        hall: The Hall sensor (amplifier included).
        speed: Robot speed (m/s).
        white: Standard complex normals of the profile draws, shape ``(draws, bins)``.
        noise: Standard normals of the sensor noise, shape ``(draws, samples)``.
        noise_v: ADC noise plus quantisation (V RMS).
        tilt: Whisker angle θ (rad).
    """

    modes: ContactModes
    hall: HallSensor
    speed: jax.Array
    white: jax.Array
    noise: jax.Array
    noise_v: float = eqx.field(static=True)
    tilt: float = eqx.field(static=True)

    def at_speed(self, speed_mps: float) -> "ContactTwin":
        """The same twin at another speed (the same random numbers; no recompilation)."""
        return eqx.tree_at(lambda t: t.speed, self, jnp.asarray(float(speed_mps)))

    @property
    def grid_n(self) -> int:
        return 2 * (self.white.shape[1] - 1)

    def ground(self, p, white):
        """``(z, ż)`` on the grid (m, m/s) of one draw for parameters ``p``."""
        n = self.grid_n
        f = np.fft.rfftfreq(n, 1 / GRID_HZ)
        # each bin carries the spectrum's integral over its width (not its value at the
        # centre: the steep spectrum would otherwise put a power that depends on the
        # grid's length into the lowest bins)
        lo = np.clip(f - GRID_HZ / n / 2, 0.5, 400.0)
        hi = np.clip(f + GRID_HZ / n / 2, 0.5, 400.0)
        band = hi > lo
        scale = self.speed * N0
        ua = jnp.where(band, lo, 1.0) / scale
        ub = jnp.where(band, hi, 2.0) / scale
        # bounded: a wild trial step must not blow the simulation up (zero slope outside)
        rough, slope = jnp.exp(jnp.clip(p[3], np.log(1e-7), np.log(1e-2))), jnp.clip(p[4], 0, 5)
        e = 1.0 - slope  # ∫ u^(−w) du = (u_b^e − u_a^e)/e, ln(u_b/u_a) at w = 1
        near = jnp.abs(e) < 1e-4
        e_safe = jnp.where(near, 1e-4, e)
        power = rough**2 * jnp.where(near, jnp.log(ub / ua), (ub**e_safe - ua**e_safe) / e_safe)
        # amplitude per bin, zero out of band (no sqrt at 0: its derivative is infinite)
        spec = jnp.where(band, jnp.sqrt(jnp.where(band, power, 1.0)) / 2, 0.0) * white
        z = jnp.fft.irfft(spec, n) * n
        zd = jnp.fft.irfft(spec * 2j * np.pi * f, n) * n
        return jnp.stack([z, zd])

    def contact(self, p) -> ContactParams:
        # k in series with K_CAP, written so that no exp overflows for a wild trial step
        k = K_CAP * jax.nn.sigmoid(p[0] - np.log(K_CAP))
        preload = jnp.exp(jnp.clip(p[1], np.log(1e-6), np.log(0.02)))
        tip_mass = 1.0 / jnp.sum(self.modes.phi_tip**2 / self.modes.modal_mass)
        kt = 1.0 / self.modes.tip_flexibility
        static = preload * kt / (kt + k)  # δ_s, the static penetration (friction aside)
        alpha = 2 * CONTACT_ZETA * jnp.sqrt(tip_mass / k) / static
        return ContactParams(stiffness=k, exponent=1.0, damping=alpha, slip_velocity=SLIP,
                             friction=jnp.exp(jnp.clip(p[2], -5.0, 1.0)), preload=preload,
                             tilt_rad=self.tilt)  # fmt: skip

    def deflection_um(self, p, white, noise):
        """Sensor deflection (µm) at 200 Hz after the settling, noise included."""
        c = self.contact(p)
        n = self.grid_n
        t = jnp.arange(n) / GRID_HZ
        inputs = ContactInputs(0.0, 1 / GRID_HZ, jnp.zeros((3, n)), self.ground(p, white),
                               self.speed)  # fmt: skip
        # static equilibrium on the mean ground (linear spring: closed form)
        cos, sin = jnp.cos(c.tilt_rad), jnp.sin(c.tilt_rad)
        lever = cos - c.friction * sin * jnp.tanh(self.speed / c.slip_velocity)
        delta = c.preload / (1 + cos * self.modes.tip_flexibility * lever * c.stiffness)
        q = self.modes.phi_tip / (self.modes.modal_mass * self.modes.omega**2)
        y0 = jnp.concatenate([q * c.stiffness * delta * lever, jnp.zeros_like(q)])
        import diffrax

        res = simulate_contact(self.modes, c, inputs, t, y0, fixed_step=True,
                               adjoint=diffrax.ForwardMode())  # fmt: skip
        step = int(GRID_HZ / RATE_HZ)
        x = res.deflection[int(SETTLE_S * GRID_HZ) :: step]
        volts = self.hall.voltage(x) + self.noise_v * noise[: x.shape[0]]
        return _to_um(volts, self.hall)

    def volts(self, p, draw: int = 0) -> jax.Array:
        """A simulated recording (V at 200 Hz) of one draw: a case of known parameters."""
        x = self.deflection_um(p, self.white[draw], self.noise[draw])
        return x * 1e-6 * self.hall.gain_v_per_m + self.hall.offset_v

    def stats(self, p) -> jax.Array:
        """Expected window statistics: the mean over the draws and their windows."""

        def one(white, noise):
            x = self.deflection_um(p, white, noise)
            m = x.shape[0] // WINDOW
            return window_stats(x[: m * WINDOW].reshape(m, WINDOW))

        s = jax.vmap(one)(self.white, self.noise)
        return jnp.mean(s.reshape(-1, s.shape[-1]), axis=0)

    @property
    def sim_windows(self) -> int:
        n_out = (self.grid_n - int(SETTLE_S * GRID_HZ)) // int(GRID_HZ / RATE_HZ)
        return self.white.shape[0] * (n_out // WINDOW)


def contact_twin(speed_mps: float, *, record: WhiskerRecord | None = None,
                 amplifier: float = 20.0, draws: int = 2, duration_s: float = 4.0,
                 seed: int = 0, noise_v_rms: float = 2.5e-4,
                 tilt_rad: float = DEFAULT_TILT_RAD) -> ContactTwin:  # fmt: skip
    """The :class:`ContactTwin` of a recording at ``speed_mps`` (s of simulation per draw:
    ``duration_s`` plus 0.5 s of settling)."""
    record = paper_record() if record is None else record
    hall = amplified_hall(record, amplifier)
    n = round((duration_s + SETTLE_S) * GRID_HZ)
    n += n % 2
    rng = np.random.default_rng(seed)
    white = rng.standard_normal((draws, n // 2 + 1)) + 1j * rng.standard_normal((draws, n // 2 + 1))
    lsb = record.adc.lsb_v
    return ContactTwin(
        modes=_first_modes(contact_modes(record.whisker()), 2),
        hall=hall,
        speed=jnp.asarray(float(speed_mps)),
        white=jnp.asarray(white),
        noise=jnp.asarray(rng.standard_normal((draws, n))),
        noise_v=float(np.hypot(noise_v_rms, lsb / np.sqrt(12))),
        tilt=float(tilt_rad),
    )


class ContactFit(NamedTuple):
    """A fit of the contact parameters (in :data:`PARAM_NAMES` order).

    Attributes:
        params: Estimate.
        sd: Standard errors (from ``JᵀJ``, priors included).
        correlation: Correlation of the estimate.
        data_information: Diagonal of the data's Fisher information (priors excluded);
            compare with ``1/PRIOR_SD²`` to see which parameters the data determine.
        chi2: Whitened data residual, summed squares (about ``stats − params`` if the
            twin describes the recording).
        steps: Optimiser steps.
        converged: Whether the optimiser met its tolerance within its steps.

    The standard errors are those of the linearised problem. On simulated recordings of
    known parameters (``benchmarks/contact_fit_recovery.py``) they are too small for the
    stiffness, the preload and the slope (the statistics admit more than one contact
    that fits, and the twin's own draws bias the slope): treat them as lower bounds, and
    the stiffness as determined only when the ground is soft and the fit converged.
    """

    params: np.ndarray
    sd: np.ndarray
    correlation: np.ndarray
    data_information: np.ndarray
    chi2: float
    steps: int
    converged: bool


@eqx.filter_jit
def _solve(twin: ContactTwin, target, white_chol, p0, max_steps: int):
    import optimistix as optx

    def residuals(p, args):
        data = jax.scipy.linalg.solve_triangular(white_chol, twin.stats(p) - target, lower=True)
        return jnp.concatenate([data, (p - PRIOR_MEAN) / PRIOR_SD])

    sol = optx.least_squares(residuals, optx.LevenbergMarquardt(rtol=1e-3, atol=1e-3), p0,
                             max_steps=max_steps, throw=False)  # fmt: skip
    jac = jax.jacfwd(residuals)(sol.value, None)
    ok = sol.result == optx.RESULTS.successful
    return sol.value, jac, residuals(sol.value, None), sol.stats["num_steps"], ok


def fit_contact(volts, speed_mps: float, *, twin: ContactTwin | None = None,
                shrink: float = 0.3, max_steps: int = 30,
                stiffness_starts: tuple[float, ...] = (),
                **twin_options) -> ContactFit:  # fmt: skip
    """Fit the contact parameters of one 200 Hz Hall recording (see the module docstring).

    Args:
        volts: The Hall voltage (V) at 200 Hz (at least 8 s: two blocks of 4 windows).
        speed_mps: The robot's speed (m/s).
        twin: A prepared :func:`contact_twin` (one per speed compiles once).
        shrink: Weight of the diagonal in the statistics' covariance (the rest is the
            sample covariance of a few windows, which alone would be noisy).
        max_steps: Levenberg–Marquardt steps at most.
        stiffness_starts: Further starting stiffnesses (N/m), each fitted, the lowest
            objective kept: a soft ground can have a second, stiffer solution.
        **twin_options: For :func:`contact_twin` when ``twin`` is not given.
    """
    twin = contact_twin(speed_mps, **twin_options) if twin is None else twin
    mean, cov = recording_stats(volts, twin.hall)
    n_obs = np.asarray(volts).size // WINDOW
    cov = (1 - shrink) * cov + shrink * np.diag(np.diag(cov))
    cov = cov * (1 / n_obs + 1 / twin.sim_windows)
    chol = np.linalg.cholesky(cov)
    best = None
    for k0 in (None, *stiffness_starts):
        p0 = PRIOR_MEAN.copy()
        if k0 is not None:
            p0[0] = np.log(k0)
        out = _solve(twin, jnp.asarray(mean), jnp.asarray(chol), jnp.asarray(p0), max_steps)
        cost = float(np.sum(np.asarray(out[2]) ** 2))
        if best is None or (np.isfinite(cost) and not cost >= best[0]):
            best = (cost, out)
    p, jac, res, steps, ok = best[1]
    jac, res = np.asarray(jac), np.asarray(res)
    ns = len(STAT_NAMES)
    if not (np.isfinite(jac).all() and np.isfinite(res).all()):
        raise FloatingPointError(
            "the contact fit's statistics are not finite at its solution (the simulation "
            "diverged); the recording may not be a whisker on the ground at this speed"
        )
    covp = np.linalg.pinv(jac.T @ jac)
    sd = np.sqrt(np.diag(covp))
    info = jac[:ns].T @ jac[:ns]
    return ContactFit(np.asarray(p), sd, covp / np.outer(sd, sd), np.diag(info),
                      float(np.sum(res[:ns] ** 2)), int(steps), bool(ok))  # fmt: skip
