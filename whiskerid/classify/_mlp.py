"""A multi-layer perceptron classifier in JAX (equinox + optax), with early stopping.

The paper's network (Section IV) is the preset :data:`PAPER_HIDDEN`: 200 inputs, five
ReLU hidden layers, a softmax over the classes and a cross-entropy loss ("seven layers"
counting input and output). The paper gives no hidden sizes; these are ours.

Training is full-batch Adam by default (minibatches optional); one jitted call runs a
chunk of epochs in ``lax.scan`` and tracks the validation loss, keeping the best
parameters; the host stops once the validation loss has not improved for ``patience``
epochs. Training and validation rows live in one padded array, told apart by row
weights, so one compilation serves every split of the same size class. The training
settings that are numbers (learning rate, weight decay, input noise) are traced
arguments, not compile-time constants: a compilation depends on the layer sizes, the
padded number of rows, the batch size, the epochs per chunk and the label smoothing only.
The label smoothing stays a constant: at its default, 0, XLA simplifies the loss and its
gradient, and a traced 0 would move trained weights in their last digits. Networks run in
float32 (the features are standardised, and float32 halves the CPU time).
"""

import itertools
from dataclasses import dataclass
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

PAPER_HIDDEN = (256, 128, 64, 32, 16)
DEFAULT_HIDDEN = (16,)


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


def init_mlp(n_in: int, hidden: tuple[int, ...], n_out: int, seed: int) -> MLP:
    """A new network with equinox's default initialisation (``U(±1/√fan_in)``) drawn by
    NumPy: no JAX compilation, so a fresh training run starts at once. Seeded."""
    rng = np.random.default_rng(seed)
    sizes = [n_in, *hidden, n_out]
    arrays = {}
    for i, (a, b) in enumerate(itertools.pairwise(sizes)):
        lim = 1.0 / np.sqrt(a)
        arrays[f"W{i}"] = rng.uniform(-lim, lim, (b, a)).astype(np.float32)
        arrays[f"b{i}"] = rng.uniform(-lim, lim, b).astype(np.float32)
    return from_arrays(arrays, sizes)


def from_arrays(arrays: dict[str, np.ndarray], sizes: list[int]) -> MLP:
    """Rebuild a network of the given layer widths from :func:`to_arrays` output.

    Raises:
        ValueError: Missing arrays, wrong shapes or non-finite values.
    """
    # Shapes only (no random initialisation to compile or run): every array is replaced.
    model = eqx.filter_eval_shape(
        MLP, sizes[0], tuple(sizes[1:-1]), sizes[-1], key=jax.random.PRNGKey(0)
    )
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
        batch_size: Minibatch size; 0 (the default) trains on the whole training set at
            every step (full batch: a few thousand windows of a few dozen features are one
            small matrix product, so an epoch is one step and training is fast).
        max_epochs: Upper bound on epochs (= steps with full batch).
        patience: Stop after this many epochs without a better validation loss.
        chunk: Epochs per jitted call (the stopping check runs between chunks).
        seed: Initialisation and shuffling seed.
        input_noise: Standard deviation of Gaussian noise added to the (standardised)
            inputs at every step: a cheap regulariser against memorising recordings.
        label_smoothing: Label smoothing of the cross-entropy targets.
        balance: Weight the loss by inverse class frequency, so that each class counts
            alike whatever the time recorded on it (exactly no change when the classes
            have equal numbers of windows). How long each terrain was driven says
            nothing about how common it is where the robot goes next; unweighted, the
            network leans to the most recorded class (BorealTC: 27 snow runs, 7 asphalt).
        ensemble: Networks trained (different seeds and validation recordings) whose
            probabilities a model averages.
        refit: After early stopping has chosen the number of epochs on validation
            recordings, train again on *all* training windows for that many epochs (the
            validation recordings are data too: holding out a fifth of the recordings cost
            3-4 points of accuracy on new recordings).
    """

    hidden: tuple[int, ...] = DEFAULT_HIDDEN
    learning_rate: float = 3e-3
    weight_decay: float = 1.0
    batch_size: int = 0
    max_epochs: int = 1500
    patience: int = 150
    chunk: int = 20
    seed: int = 0
    input_noise: float = 0.3
    label_smoothing: float = 0.0
    balance: bool = True
    ensemble: int = 1
    refit: bool = True


#: The paper pipeline's settings: its five-layer network, minibatches of 128, no extra
#: regularisation.
PAPER_CONFIG = TrainConfig(hidden=PAPER_HIDDEN, learning_rate=2e-3, weight_decay=1e-4,
                           batch_size=128, max_epochs=300, patience=25, chunk=10,
                           input_noise=0.0, balance=False)  # fmt: skip


def default_config(features: str = "fitted") -> TrainConfig:
    """Training settings for a feature pipeline: :data:`PAPER_CONFIG` for ``paper``; for
    ``fitted`` one narrow hidden layer (16) with strong weight decay and input noise, full
    batch, refitted on all data, classes weighted alike. Chosen on a separately seeded
    synthetic dataset, split by recording: the features separate the terrains almost
    linearly, and wider or deeper networks (64-32, 128-64) learnt the recordings instead
    (3-4 points worse on new ones); an ensemble of three gained little for three times the
    training time. Weight decay 3 did better on BorealTC (runs held out, on top of the class
    weights: +1.3 points per window) but cost 0.8 on the synthetic set (seed 7)."""
    return PAPER_CONFIG if features == "paper" else TrainConfig()


@dataclass
class TrainResult:
    """A trained network and how training went."""

    model: MLP
    epochs: int
    best_epoch: int
    best_val_loss: float
    val_accuracy: float
    history: list[float]


class _Settings(NamedTuple):
    """The numeric training settings: float32 scalars traced by the jitted chunk, and the
    label smoothing, a Python float and so a constant of it (see the module docstring)."""

    learning_rate: Float[Array, ""]
    weight_decay: Float[Array, ""]
    input_noise: Float[Array, ""]
    label_smoothing: float

    @classmethod
    def of(cls, config: "TrainConfig") -> "_Settings":
        values = (config.learning_rate, config.weight_decay, config.input_noise)
        traced = (jnp.asarray(v, jnp.float32) for v in values)
        return cls(*traced, float(config.label_smoothing))


def _optimizer(settings: _Settings):
    """AdamW with the (traced) step size and weight decay; its state does not depend on
    them, so one built from any numbers initialises it."""
    import optax  # training only: a model that only predicts (the stream) never loads it

    return optax.adamw(settings.learning_rate, weight_decay=settings.weight_decay)


def _loss(model, x, y, weights, smoothing=0.0):
    """Weighted mean cross-entropy; ``weights`` is per row (0 leaves a row out)."""
    import optax

    logits = jax.vmap(model)(x)
    target = optax.smooth_labels(jax.nn.one_hot(y, logits.shape[-1], dtype=logits.dtype), smoothing)
    ce = optax.softmax_cross_entropy(logits, target)
    return jnp.sum(weights * ce) / jnp.maximum(jnp.sum(weights), 1e-12)


@eqx.filter_jit
def _run_chunk(params, static, opt_state, best, key, data, settings: _Settings, n_epochs: int,
               batch: int):  # fmt: skip
    """``n_epochs`` epochs of Adam; keeps the parameters of the best validation loss.

    ``data = (x, y, w_train, w_val)``: training and validation rows share one array and
    are told apart by their row weights, so the compiled function depends only on the
    (padded) number of rows, not on how a split fell: ensemble members, repeats of the
    paper protocol and the folds of an evaluation reuse one compilation.
    """
    x, y, w_train, w_val, bank, epoch0 = data
    opt, noise, smoothing = _optimizer(settings), settings.input_noise, settings.label_smoothing
    n = x.shape[0]
    n_batches = max(n // batch, 1)

    def step(c, args):
        p, s = c
        idx, eps = args
        xb = x[idx] + noise * eps[idx]
        grads = eqx.filter_grad(
            lambda q: _loss(eqx.combine(q, static), xb, y[idx], w_train[idx], smoothing)
        )(p)
        updates, s = opt.update(grads, s, p)
        return (eqx.apply_updates(p, updates), s), None

    def epoch(carry, args):
        params, opt_state, best = carry
        key, e = args
        # Input noise from a fixed bank of Gaussian draws, rolled by an epoch-dependent
        # amount along rows and features: every row gets a fresh draw each epoch, and no
        # random generator is compiled into the loop (that tripled the compile time).
        eps = jnp.roll(bank, (e * 7919 % n, e * 31 % x.shape[1]), axis=(0, 1))
        if batch >= n:  # full batch: one step, no shuffling or gathering (compiles faster)
            (params, opt_state), _ = step((params, opt_state), (slice(None), eps))
        else:
            perm = jax.random.permutation(key, n)[: n_batches * batch]
            perm = perm.reshape(n_batches, batch)
            (params, opt_state), _ = jax.lax.scan(
                lambda c, idx: step(c, (idx, eps)), (params, opt_state), perm
            )
        val = _loss(eqx.combine(params, static), x, y, w_val)
        best_params, best_loss = best
        better = val < best_loss
        best_params = jax.tree_util.tree_map(
            lambda a, b: jnp.where(better, a, b), params, best_params
        )
        return (params, opt_state, (best_params, jnp.minimum(val, best_loss))), (val, better)

    keys = jax.random.split(key, n_epochs)
    epochs = epoch0 + jnp.arange(n_epochs)
    carry, (vals, better) = jax.lax.scan(epoch, (params, opt_state, best), (keys, epochs))
    return carry, vals, better


def _pad_rows(n: int) -> int:
    """Rows after padding: the next multiple of 256 (fewer distinct compiled shapes)."""
    return -(-n // 256) * 256


def train_mlp(
    x: Float[Array, "n features"],
    y: Int[Array, " n"],
    x_val: Float[Array, "m features"],
    y_val: Int[Array, " m"],
    n_classes: int,
    config: TrainConfig = TrainConfig(),
    *,
    epochs: int | None = None,
) -> TrainResult:
    """Train an :class:`MLP` on standardised features with early stopping on ``(x_val, y_val)``.

    With ``epochs`` given, trains for that many epochs (rounded up to whole chunks) and
    keeps the final parameters instead: the refit on all data once early stopping has
    chosen the length (``x_val`` may then be empty). Deterministic for a given
    ``config.seed`` (and inputs).
    """
    x = np.asarray(x, np.float32)
    xv = np.asarray(x_val, np.float32)
    y, yv = np.asarray(y, np.int32), np.asarray(y_val, np.int32)
    n, m = len(y), len(yv)
    rows = _pad_rows(n + m)
    xa = np.zeros((rows, x.shape[1]), np.float32)
    xa[:n], xa[n : n + m] = x, xv
    ya = np.zeros(rows, np.int32)
    ya[:n], ya[n : n + m] = y, yv
    counts = np.bincount(y, minlength=n_classes).astype(np.float32)
    cw = (
        np.where(counts > 0, counts.sum() / (n_classes * np.maximum(counts, 1)), 1.0)
        if config.balance
        else np.ones(n_classes, np.float32)
    )
    w_train = np.zeros(rows, np.float32)
    w_train[:n] = cw[y]
    w_val = np.zeros(rows, np.float32)
    w_val[n : n + m] = cw[yv] if m else 0.0
    bank = np.random.default_rng([config.seed, 1]).standard_normal(xa.shape).astype(np.float32)
    data = [jnp.asarray(a) for a in (xa, ya, w_train, w_val, bank)]
    # Keys of the "rbg" generator: XLA's own bit generator compiles in a fraction of the
    # time threefry's unrolled rounds take inside the scanned epoch (seconds saved).
    key = jax.random.key(config.seed, impl="rbg")
    model = init_mlp(x.shape[1], tuple(config.hidden), n_classes, config.seed)
    params, static = eqx.partition(model, eqx.is_array)
    settings = _Settings.of(config)
    opt_state = _optimizer(settings).init(params)
    best = (params, jnp.asarray(jnp.inf, jnp.float32))
    batch = rows if config.batch_size <= 0 else min(config.batch_size, rows)
    history: list[float] = []
    best_epoch = 0
    fixed = epochs is not None
    stop = max(int(epochs), 1) if fixed else config.max_epochs
    epochs = 0
    while epochs < stop:
        key, sub = jax.random.split(key)
        (params, opt_state, best), vals, better = _run_chunk(
            params,
            static,
            opt_state,
            best,
            sub,
            (*data, jnp.asarray(epochs, jnp.int32)),
            settings,
            config.chunk,
            batch,
        )
        vals, better = np.asarray(vals), np.asarray(better)
        history.extend(float(v) for v in vals)
        if better.any():
            best_epoch = epochs + int(np.flatnonzero(better)[-1]) + 1
        epochs += config.chunk
        if not fixed and epochs - best_epoch >= config.patience:
            break
    if fixed:
        best_epoch = epochs
    model = eqx.combine(params if fixed else best[0], static)
    pred = np.argmax(np.asarray(predict_proba(model, xv)), axis=1)
    acc = float(np.mean(pred == yv)) if m else 0.0
    return TrainResult(model, epochs, best_epoch, float(best[1]), acc, history)


def predict_proba(model: MLP, x: Float[Array, "n features"]) -> np.ndarray:
    """Class probabilities (softmax of the logits), shape ``(n, classes)``.

    The rows are padded to :func:`pad_rows` (and the padding dropped), so that the
    compiled function serves every batch of a size class: validation sets and folds of
    different sizes do not each compile their own.
    """
    x = np.asarray(x, np.float32)
    padded = np.zeros((pad_rows(len(x)), *x.shape[1:]), np.float32)
    padded[: len(x)] = x
    return np.asarray(_predict_proba(model, padded))[: len(x)]


@eqx.filter_jit
def _predict_proba(model: MLP, x: Float[Array, "n features"]) -> Float[Array, "n classes"]:
    return jax.nn.softmax(jax.vmap(model)(x), axis=-1)


def pad_rows(n: int) -> int:
    """Rows a batch of ``n`` is padded to: the next power of two from 8 to 256, then the
    next multiple of 256 (few distinct compiled shapes, little wasted work)."""
    if n > 256:
        return _pad_rows(n)
    return max(8, 1 << max(n - 1, 0).bit_length())
