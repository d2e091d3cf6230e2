"""dsfec_jax: efficient, deployable radar object detectors in JAX/Flax."""

__version__ = "0.1.0"

# Nothing runs at import. The commands that run XLA restart once with glibc and JAX settings for
# XLA's CPU buffers when they start (core/host_memory.prepare_xla_process); the map service and
# library users keep the defaults.
