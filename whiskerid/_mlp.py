"""A multi-layer perceptron classifier in JAX (equinox + optax), with early stopping.

The paper's network (Section IV) is the preset :data:`PAPER_HIDDEN`: 200 inputs, five
ReLU hidden layers, a softmax over the classes and a cross-entropy loss ("seven layers"
counting input and output). The paper gives no hidden sizes; these are ours.

Training is full-dataset Adam over shuffled minibatches; one jitted call runs a chunk of
epochs in ``lax.scan`` and tracks the validation loss, keeping the best parameters; the
host stops once the validation loss has not improved for ``patience`` epochs. Networks run
in float32 (the features are standardised, and float32 halves the CPU time).
"""

import functools
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float, Int

PAPER_HIDDEN = (256, 128, 64, 32, 16)
DEFAULT_HIDDEN = (64, 32)


class MLP(eqx.Module):
    """Fully connected ReLU network returning logits (softmax them for probabilities)."""

    layers: list

    def __init__(self, n_in: int, hidden: tuple[int, ...], n_out: int, *, key):
        sizes = [n_in, *hidden, n_out]
        keys = jax.random.split(key, len(sizes) - 1)
        self.layers = [
            eqx.nn.Linear(a, b, key=k, dtype=jnp.float32)
            for a, b, k in zip(sizes[:-1], sizes[1:], keys, strict=True)
        ]

    def __call__(self, x: Float[Array, " features"]) -> Float[Array, " classes"]:
        for layer in self.layers[:-1]:
            x = jax.nn.relu(layer(x))
        return self.layers[-1](x)

    @property
    def sizes(self) -> list[int]:
        """Layer widths, input first."""
        return [self.layers[0].in_features] + [lay.out_features for lay in self.layers]


def to_arrays(model: MLP) -> dict[str, np.ndarray]:
    """Weights as named NumPy arrays (``W0, b0, W1, ...``) for an NPZ file."""
    out = {}
    for i, lay in enumerate(model.layers):
        out[f"W{i}"] = np.asarray(lay.weight)
        out[f"b{i}"] = np.asarray(lay.bias)
    return out


def from_arrays(arrays: dict[str, np.ndarray], sizes: list[int]) -> MLP:
    """Rebuild a network of the given layer widths from :func:`to_arrays` output.

    Raises:
        ValueError: Missing arrays, wrong shapes or non-finite values.
    """
    model = MLP(sizes[0], tuple(sizes[1:-1]), sizes[-1], key=jax.random.PRNGKey(0))
    layers = []
    for i, lay in enumerate(model.layers):
        w, b = arrays.get(f"W{i}"), arrays.get(f"b{i}")
        if w is None or b is None:
            raise ValueError(f"weights W{i}/b{i} are missing")
        if w.shape != lay.weight.shape or b.shape != lay.bias.shape:
            raise ValueError(
                f"layer {i} has shape {w.shape}/{b.shape}, "
                f"expected {lay.weight.shape}/{lay.bias.shape}"
            )
        if not (np.isfinite(w).all() and np.isfinite(b).all()):
            raise ValueError(f"layer {i} holds non-finite weights")
        lay = eqx.tree_at(lambda m: (m.weight, m.bias), lay,
                          (jnp.asarray(w, jnp.float32), jnp.asarray(b, jnp.float32)))  # fmt: skip
        layers.append(lay)
    return eqx.tree_at(lambda m: m.layers, model, layers)


@dataclass(frozen=True)
class TrainConfig:
    """Training settings.

    Attributes:
        hidden: Hidden layer widths (five in the paper's network).
        learning_rate: Adam step size.
        weight_decay: Decoupled weight decay (AdamW).
        batch_size: Minibatch size (the whole set when smaller).
        max_epochs: Upper bound on epochs.
        patience: Stop after this many epochs without a better validation loss.
        chunk: Epochs per jitted call (the stopping check runs between chunks).
        seed: Initialisation and shuffling seed.
        input_noise: Standard deviation of Gaussian noise added to the (standardised)
            inputs of every minibatch: a cheap regulariser against memorising recordings.
        label_smoothing: Label smoothing of the cross-entropy targets.
        balance: Weight the loss by inverse class frequency (unbalanced datasets).
        ensemble: Networks trained (different seeds and validation recordings) whose
            probabilities a model averages.
    """

    hidden: tuple[int, ...] = DEFAULT_HIDDEN
    learning_rate: float = 2e-3
    weight_decay: float = 1e-2
    batch_size: int = 128
    max_epochs: int = 300
    patience: int = 25
    chunk: int = 10
    seed: int = 0
    input_noise: float = 0.3
    label_smoothing: float = 0.0
    balance: bool = False
    ensemble: int = 1


#: The paper pipeline's settings: its five-layer network, no extra regularisation.
PAPER_CONFIG = TrainConfig(hidden=PAPER_HIDDEN, weight_decay=1e-4, input_noise=0.0, balance=False)


def default_config(features: str = "fitted") -> TrainConfig:
    """Training settings for a feature pipeline: :data:`PAPER_CONFIG` for ``paper``; for
    ``fitted`` three small networks with weight decay and input noise (chosen on validation
    recordings inside the training data: wider and deeper networks memorised recordings)."""
    return PAPER_CONFIG if features == "paper" else TrainConfig(ensemble=3)


@dataclass
class TrainResult:
    """A trained network and how training went."""

    model: MLP
    epochs: int
    best_epoch: int
    best_val_loss: float
    val_accuracy: float
    history: list[float]


@functools.lru_cache(maxsize=8)
def _optimizer(learning_rate: float, weight_decay: float):
    # Cached: the optimiser is a static argument of the jitted chunk, so a new one each
    # call would recompile.
    return optax.adamw(learning_rate, weight_decay=weight_decay)


def _loss(model, x, y, weights, smoothing=0.0):
    logits = jax.vmap(model)(x)
    target = optax.smooth_labels(jax.nn.one_hot(y, logits.shape[-1], dtype=logits.dtype), smoothing)
    ce = optax.softmax_cross_entropy(logits, target)
    w = weights[y]
    return jnp.sum(w * ce) / jnp.sum(w)


@eqx.filter_jit
def _run_chunk(params, static, opt_state, best, key, data, n_epochs: int, batch: int, opt,
               noise: float, smoothing: float):  # fmt: skip
    """``n_epochs`` epochs of minibatch Adam; keeps the parameters of the best validation loss."""
    x, y, xv, yv, weights = data
    n = x.shape[0]
    n_batches = max(n // batch, 1)

    def epoch(carry, key):
        params, opt_state, best = carry
        key_perm, key_noise = jax.random.split(key)
        perm = jax.random.permutation(key_perm, n)[: n_batches * batch].reshape(n_batches, batch)
        noise_keys = jax.random.split(key_noise, n_batches)

        def step(c, args):
            p, s = c
            idx, k = args
            xb = x[idx] + noise * jax.random.normal(k, x[idx].shape, x.dtype)
            grads = eqx.filter_grad(
                lambda q: _loss(eqx.combine(q, static), xb, y[idx], weights, smoothing)
            )(p)
            updates, s = opt.update(grads, s, p)
            return (eqx.apply_updates(p, updates), s), None

        (params, opt_state), _ = jax.lax.scan(step, (params, opt_state), (perm, noise_keys))
        val = _loss(eqx.combine(params, static), xv, yv, weights)
        best_params, best_loss = best
        better = val < best_loss
        best_params = jax.tree_util.tree_map(
            lambda a, b: jnp.where(better, a, b), params, best_params
        )
        return (params, opt_state, (best_params, jnp.minimum(val, best_loss))), (val, better)

    keys = jax.random.split(key, n_epochs)
    carry, (vals, better) = jax.lax.scan(epoch, (params, opt_state, best), keys)
    return carry, vals, better


def train_mlp(
    x: Float[Array, "n features"],
    y: Int[Array, " n"],
    x_val: Float[Array, "m features"],
    y_val: Int[Array, " m"],
    n_classes: int,
    config: TrainConfig = TrainConfig(),
) -> TrainResult:
    """Train an :class:`MLP` on standardised features with early stopping on ``(x_val, y_val)``.

    Deterministic for a given ``config.seed`` (and inputs).
    """
    x = jnp.asarray(x, jnp.float32)
    xv = jnp.asarray(x_val, jnp.float32)
    y, yv = jnp.asarray(y, jnp.int32), jnp.asarray(y_val, jnp.int32)
    key_init, key = jax.random.split(jax.random.PRNGKey(config.seed))
    model = MLP(x.shape[1], tuple(config.hidden), n_classes, key=key_init)
    params, static = eqx.partition(model, eqx.is_array)
    opt = _optimizer(config.learning_rate, config.weight_decay)
    opt_state = opt.init(params)
    best = (params, jnp.asarray(jnp.inf, jnp.float32))
    batch = min(config.batch_size, x.shape[0])
    counts = np.bincount(np.asarray(y), minlength=n_classes).astype(np.float32)
    weights = (
        jnp.asarray(
            np.where(counts > 0, counts.sum() / (n_classes * np.maximum(counts, 1)), 1.0),
            jnp.float32,
        )
        if config.balance
        else jnp.ones(n_classes, jnp.float32)
    )
    history: list[float] = []
    best_epoch, epochs = 0, 0
    while epochs < config.max_epochs:
        key, sub = jax.random.split(key)
        (params, opt_state, best), vals, better = _run_chunk(
            params,
            static,
            opt_state,
            best,
            sub,
            (x, y, xv, yv, weights),
            config.chunk,
            batch,
            opt,
            config.input_noise,
            config.label_smoothing,
        )
        vals, better = np.asarray(vals), np.asarray(better)
        history.extend(float(v) for v in vals)
        if better.any():
            best_epoch = epochs + int(np.flatnonzero(better)[-1]) + 1
        epochs += config.chunk
        if epochs - best_epoch >= config.patience:
            break
    model = eqx.combine(best[0], static)
    acc = float(jnp.mean(jnp.argmax(jax.vmap(model)(xv), axis=1) == yv))
    return TrainResult(model, epochs, best_epoch, float(best[1]), acc, history)


@eqx.filter_jit
def predict_proba(model: MLP, x: Float[Array, "n features"]) -> Float[Array, "n classes"]:
    """Class probabilities (softmax of the logits)."""
    return jax.nn.softmax(jax.vmap(model)(jnp.asarray(x, jnp.float32)), axis=-1)
