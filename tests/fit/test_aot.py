"""A cached program takes its arguments as one flat buffer per dtype: every leaf comes back
whole (values, dtype, shape), and the program computes what the function computes."""

import jax.numpy as jnp
import numpy as np

from whiskerid.fit._numerics._aot import _pack, _packing, _unpack, cached_call


def _leaves():
    rng = np.random.default_rng(3)
    return [
        rng.normal(size=7),
        np.asarray(2.5),
        np.arange(6, dtype=np.int64).reshape(2, 3),
        rng.normal(size=(3, 2)),
        np.zeros(0),
        np.asarray([True, False, True]),
        np.asarray(-4, dtype=np.int64),
    ]


def test_the_leaves_come_back_whole_from_their_buffers():
    leaves = _leaves()
    packing = _packing(leaves)
    buffers = _pack(leaves, packing)
    # float64, int64 and bool: three buffers, each holding its leaves' numbers in order
    assert [b.dtype for b in buffers] == [np.float64, np.int64, np.bool_]
    assert [b.size for b in buffers] == [7 + 1 + 6 + 0, 6 + 1, 3]
    for got, want in zip(_unpack(buffers, packing), leaves, strict=True):
        assert got.dtype == want.dtype and got.shape == want.shape
        np.testing.assert_array_equal(got, want)


def test_a_cached_call_computes_what_its_function_computes():
    def fn(a, b, mask):
        return {"s": jnp.sum(a * b["x"]) + b["k"], "m": jnp.where(mask, a[:3], -1.0)}

    a = np.linspace(0.0, 1.0, 5)
    b = {"x": np.arange(5.0), "k": np.asarray(3, dtype=np.int64)}
    mask = np.asarray([True, False, True])
    got = cached_call("test-packing", fn, (a, b, mask))
    want = fn(a, b, mask)
    for k in want:
        np.testing.assert_array_equal(np.asarray(got[k]), np.asarray(want[k]))
