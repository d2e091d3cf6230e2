"""`python -m dsfec_jax.deploy.bench ...`: one bench worker, launched by `workers.run` once per
thread count (users run `dsfec bench`)."""

from ...core.host_memory import prepare_xla_process
from .workers import main

if __name__ == "__main__":
    prepare_xla_process()  # it runs XLA: glibc's and JAX's settings first (core/host_memory.py)
    raise SystemExit(main())
