"""dsfec_jax: efficient, deployable radar object detectors in JAX/Flax."""

import importlib.util as _importlib_util
import sys as _sys

__version__ = "0.1.0"

# Nothing runs at import. The commands that run XLA restart once with glibc and JAX settings for
# XLA's CPU buffers when they start (core/host_memory.prepare_xla_process); the map service and
# library users keep the defaults.

# The one exception is this check, which only looks packages up (find_spec imports nothing): a
# Python without the project's dependencies (the system python instead of the environment's)
# otherwise fails deep inside some module with "No module named 'jax'" and no hint of the cause.
_REQUIRED = ("jax", "flax", "optax", "numpy")
_missing = [name for name in _REQUIRED if _importlib_util.find_spec(name) is None]
if _missing:
    raise ImportError(
        f"dsfec_jax needs {', '.join(_missing)}, which {_sys.executable} does not have: run the project "
        f"with the environment it was installed into (`. .venv/bin/activate`, or `.venv/bin/dsfec` / "
        f"`.venv/bin/python -m ...`), or install it there with `pip install -e .` (README: Set-up)")
