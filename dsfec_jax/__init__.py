"""dsfec_jax: efficient, deployable radar object detectors in JAX/Flax."""

from .core import host_memory as _host_memory

__version__ = "0.1.0"

# The project's commands restart once with glibc and JAX settings for XLA's CPU buffers (huge
# pages, buffers kept between calls; core/host_memory.py: 1.3-1.45x and then ~1.1x on a
# training step); importing the library elsewhere changes nothing.
_host_memory.relaunch_project_command()
