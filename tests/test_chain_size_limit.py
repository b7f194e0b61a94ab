"""A file-size limit (``ulimit -f``) is a full disk for the chain: HDF5 crashed the process
(SIGSEGV) when a step's write failed with EFBIG; the step is not begun, the chain stays
whole and readable."""

import errno
import resource

import numpy as np
import pytest


def test_the_chain_stops_whole_before_the_file_size_limit(tmp_path, monkeypatch):
    import emcee

    from whiskerid.posterior import _sample

    path = tmp_path / "chain.h5"
    be = _sample._checked_backend(emcee)(str(path), name="whiskerid")
    be.reset(4, 2)
    be.grow(2, None)
    state = emcee.State(np.ones((4, 2)), log_prob=np.zeros(4),
                        random_state=np.random.RandomState(0).get_state())  # fmt: skip
    be.save_step(state, np.ones(4, bool))
    limit = path.stat().st_size + 1000  # room for a little, not for a step's margin
    monkeypatch.setattr(resource, "getrlimit", lambda which: (limit, limit))
    with pytest.raises(OSError, match="file-size limit") as err:
        be.save_step(state, np.ones(4, bool))
    assert err.value.errno == errno.EFBIG
    again = emcee.backends.HDFBackend(str(path), name="whiskerid", read_only=True)
    assert again.iteration == 1 and again.get_chain().shape == (1, 4, 2)
