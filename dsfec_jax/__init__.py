"""dsfec_jax: efficient, deployable radar object detectors in JAX/Flax."""

__version__ = "0.1.0"
