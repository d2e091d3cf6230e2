"""Run small numpy matrix products on one BLAS thread.

The host data path (the RD simulator's (256 x K) @ (K x 512) products, a few MFLOP each) gains
nothing from OpenBLAS's threads, and on a busy 2-core box its spinning workers fight XLA and each
other (the generator's rate with each pool: docs/range-doppler.md; re-measure: `python -m
dsfec_jax.data inspect --source rd-synthetic` prints maps/s). threadpoolctl (the maintained way to cap
native pools at run time) costs little per `with`.
"""

from __future__ import annotations

import contextlib
import functools


@functools.lru_cache(maxsize=1)
def _controller():
    from threadpoolctl import ThreadpoolController
    return ThreadpoolController()


@contextlib.contextmanager
def single_threaded_blas():
    with _controller().limit(limits=1, user_api="blas"):
        yield
