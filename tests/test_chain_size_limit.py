"""A file-size limit (``ulimit -f``) is a full disk for the chain: HDF5 crashed the process
(SIGSEGV) when a step's write failed with EFBIG; a checkpoint is refused short of the room,
the last one on disk stays whole and readable."""

import errno
import resource

import numpy as np
import pytest
from helpers import one_step_chain


def test_the_chain_stops_whole_before_the_file_size_limit(tmp_path, monkeypatch):
    import emcee

    path = tmp_path / "chain.h5"
    be, state = one_step_chain(path)
    limit = path.stat().st_size + 1000  # room for a little, not for a step's margin
    monkeypatch.setattr(resource, "getrlimit", lambda which: (limit, limit))
    be.save_step(state, np.ones(4, bool))  # in memory: the first step was saved just now
    with pytest.raises(OSError, match="file-size limit") as err:
        be.checkpoint()
    assert err.value.errno == errno.EFBIG
    again = emcee.backends.HDFBackend(str(path), name="whiskerid", read_only=True)
    assert again.iteration == 1 and again.get_chain().shape == (1, 4, 2)
