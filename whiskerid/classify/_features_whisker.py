"""Whisker-aware pieces of the features: windows through a per-bin channel filter (the
whisker divided out and recoloured), extended at their edges by a linear predictor; the
base motion's band levels; the noise floor and the noise that matches it; windows as
another whisker would have recorded them; and the features of two channels together.
"""

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

_EPS = 1e-12  # floor of divisions and logs
_COHERENCE_BANDS = 4  # coherence bands of the cross-channel features


def through_filter(xs, response, extend: bool = False):
    """Windows ``(channels, n)`` through a per-bin channel matrix ``(bins, ch, ch)`` given
    on the grid of a ``2n``-point FFT. The channels' means are removed first.

    Args:
        xs: The windows.
        response: The filter, per bin.
        extend: Extend each window by half a window of its own continuation at each
            end, tapered to zero (:func:`extend_window`), and keep the filtered middle; else
            pad with zeros (a linear, not circular, filter of the window alone, which
            steps at the window's edges).
    """
    n = xs.shape[-1]
    x = xs - jnp.mean(xs, axis=-1, keepdims=True)
    lead = n // 2 if extend else 0
    x = extend_window(x) if extend else x
    spec = jnp.fft.rfft(x, 2 * n, axis=-1)
    y = jnp.fft.irfft(jnp.einsum("bij,jb->ib", response, spec), 2 * n, axis=-1)
    return y[:, lead : lead + n]


#: Order of the linear predictor that extends a window at its edges (:func:`extend_window`):
#: a few resonances' worth of poles.
EXTEND_ORDER = 12
#: Its ridge, relative to the mean diagonal of the normal equations: keeps the predictor's
#: poles inside the unit circle on noisy windows.
EXTEND_RIDGE = 1e-3


def extend_window(x) -> jax.Array:
    """Windows ``(channels, n)`` (zero mean) with ``m = n // 2`` samples added at each end,
    shape ``(channels, n + 2m)``: each channel's continuation by a linear predictor of
    order :data:`EXTEND_ORDER` fitted to the window itself (forward and backward, least
    squares with a ridge), clipped to the window's largest magnitude and tapered to zero
    by a half cosine. A whisker's window is a few lightly damped resonances, which such a
    predictor carries on across the edge; through a ``2n``-point circular filter the
    joins of the extension lie half a window from the window, where filters of a
    whisker's response have rung down."""
    n = x.shape[-1]
    m, p = n // 2, min(EXTEND_ORDER, n // 4)
    lags = jnp.arange(1, p + 1)[None, :]
    fwd_rows = jnp.arange(p, n)[:, None] - lags  # x[t] from x[t−1] … x[t−p]
    bwd_rows = jnp.arange(0, n - p)[:, None] + lags  # x[t] from x[t+1] … x[t+p]
    taper = 0.5 * (1 + jnp.cos(jnp.pi * jnp.arange(1, m + 1) / (m + 1)))  # 1 → 0

    def one(c):
        a_mat = jnp.concatenate([c[fwd_rows], c[bwd_rows]])
        b_vec = jnp.concatenate([c[p:], c[: n - p]])
        gram = a_mat.T @ a_mat
        ridge = EXTEND_RIDGE * jnp.trace(gram) / p + _EPS
        coef = jnp.linalg.solve(gram + ridge * jnp.eye(p), a_mat.T @ b_vec)

        def step(state, _):
            nxt = state @ coef
            return jnp.concatenate([nxt[None], state[:-1]]), nxt

        _, after = jax.lax.scan(step, c[::-1][:p], None, length=m)
        _, before = jax.lax.scan(step, c[:p], None, length=m)
        lim = jnp.max(jnp.abs(c))
        after, before = jnp.clip(after, -lim, lim), jnp.clip(before, -lim, lim)
        return jnp.concatenate([(before * taper)[::-1], c, after * taper])

    return jax.vmap(one)(x)


def base_band_levels(base, rate_hz, edges) -> jax.Array:
    """Mean-square base acceleration in each band ``[edges[k], edges[k+1])`` in dB re
    1 (m/s²)²: the Hann-windowed periodogram summed over the band's bins (``base``:
    samples on the last axis)."""
    n = base.shape[-1]
    w = jnp.hanning(n)
    x = base - jnp.mean(base, axis=-1, keepdims=True)
    spec = jnp.fft.rfft(x * w, axis=-1)
    power = 2 * jnp.abs(spec) ** 2 / (jnp.sum(w**2) * n)  # mean square per bin
    f = jnp.fft.rfftfreq(n, 1.0 / rate_hz)
    inside = (f[None, :] >= edges[:-1, None]) & (f[None, :] < edges[1:, None])
    inside = inside.at[-1].set(inside[-1] | (f == edges[-1]))
    return 10 * jnp.log10(power @ inside.T.astype(power.dtype) + 1e-20)


def rerecorded(windows, response, floor_shape, *, extend: bool, seed: int) -> np.ndarray:
    """Windows ``(n, *window_shape)`` as another whisker would have recorded the same base
    motion (:meth:`WhiskerResponse.rerecord`): each through ``response`` (per bin of a
    ``2 × window``-point FFT, ``(bins, channels, channels)``; ``extend`` as in
    :func:`through_filter`), plus white noise shaped by ``floor_shape`` (``(bins,
    channels)``) times the window's own floor (:func:`noise_floor`), drawn from ``seed``.
    """
    x = jnp.asarray(windows, dtype=float)
    many = x if x.ndim == 3 else x[:, None]
    key = jax.random.PRNGKey(seed)
    out = _rerecorded(many, jnp.asarray(response), jnp.asarray(floor_shape), extend, key)
    return np.asarray(out if x.ndim == 3 else out[:, 0])


@partial(jax.jit, static_argnums=3)
def _rerecorded(xs, response, floor_shape, extend, key):
    n = xs.shape[-1]
    filtered = jax.vmap(lambda w: through_filter(w, response, extend))(xs)
    white = jax.random.normal(key, (*xs.shape[:-1], 2 * n), dtype=xs.dtype)
    shaped = jnp.fft.irfft(jnp.fft.rfft(white, axis=-1) * floor_shape.T, 2 * n, axis=-1)
    return filtered + shaped[..., :n] * jnp.sqrt(jax.vmap(noise_floor)(xs))[..., None]


#: Percentile of a window's own power spectrum taken as its noise floor: most bins of a
#: whisker's window hold the resonance, the texture or the drivetrain; the quietest fifth
#: holds little but the floor.
FLOOR_PERCENTILE = 20.0


def noise_floor(xs) -> jax.Array:
    """Per channel, the noise floor of windows ``(channels, n)`` as a per-sample variance
    (codes²): the :data:`FLOOR_PERCENTILE` th percentile of the Hann-windowed power
    spectrum (bins 1 … n/2, normalised so that white noise reads its variance), divided by
    that percentile of the exponential distribution a noise bin's power follows, so that
    white noise reads its variance."""
    n = xs.shape[-1]
    w = jnp.hanning(n)
    x = xs - jnp.mean(xs, axis=-1, keepdims=True)
    power = jnp.abs(jnp.fft.rfft(x * w, axis=-1)) ** 2 / jnp.sum(w**2)
    quantile = -np.log1p(-FLOOR_PERCENTILE / 100)
    return jnp.percentile(power[:, 1:], FLOOR_PERCENTILE, axis=-1) / quantile


def matched_noise(xs, dither) -> jax.Array:
    """Noise that lifts the floor of windows ``(channels, n)`` by ``dither²`` times their
    own floor (:func:`noise_floor`), shaped per bin of a ``2n``-point FFT. Seeded by the
    window's content: the same window always gets the same noise."""
    n = xs.shape[-1]
    seed = jax.lax.bitcast_convert_type(jnp.sum(xs).astype(jnp.float32), jnp.uint32)
    key = jax.random.fold_in(jax.random.PRNGKey(0), seed)
    white = jax.random.normal(key, (xs.shape[0], 2 * n), dtype=xs.dtype)
    shaped = jnp.fft.irfft(jnp.fft.rfft(white, axis=-1) * dither.T, 2 * n, axis=-1)[:, :n]
    return shaped * jnp.sqrt(noise_floor(xs))[:, None]


def _cross_features(a, b):
    """Coherence in four equal bands (Welch within the window), the motion ellipse and the
    log power ratio of two zero-mean channels."""
    n = a.shape[-1]
    seg = max(n // 4, 8)
    hop = seg // 2
    starts = range(0, n - seg + 1, hop)
    w = jnp.hanning(seg)
    fa = jnp.stack([jnp.fft.rfft(a[s : s + seg] * w) for s in starts])
    fb = jnp.stack([jnp.fft.rfft(b[s : s + seg] * w) for s in starts])
    saa = jnp.mean(jnp.abs(fa) ** 2, axis=0)[1:]
    sbb = jnp.mean(jnp.abs(fb) ** 2, axis=0)[1:]
    sab = jnp.mean(fa * jnp.conj(fb), axis=0)[1:]
    coh = jnp.abs(sab) ** 2 / jnp.maximum(saa * sbb, _EPS)
    weight = saa + sbb
    bands = jnp.array_split(jnp.arange(coh.shape[0]), _COHERENCE_BANDS)
    coh_b = [jnp.sum(coh[i] * weight[i]) / jnp.maximum(jnp.sum(weight[i]), _EPS) for i in bands]
    caa, cbb, cab = jnp.mean(a * a), jnp.mean(b * b), jnp.mean(a * b)
    two_theta = jnp.arctan2(2 * cab, caa - cbb)
    root = jnp.sqrt((caa - cbb) ** 2 + 4 * cab**2)
    big, small = 0.5 * (caa + cbb + root), 0.5 * (caa + cbb - root)
    ratio = jnp.sqrt(jnp.maximum(small, 0.0) / jnp.maximum(big, _EPS))
    power_ratio = jnp.log(caa + _EPS) - jnp.log(cbb + _EPS)
    return jnp.stack([*coh_b, jnp.cos(two_theta), jnp.sin(two_theta), ratio, power_ratio])
