"""`python -m dsfec_jax.deploy.bench ...`: one bench worker, launched by `workers.run` once per
thread count (users run `dsfec bench`)."""

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from ...core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from .workers import main

if __name__ == "__main__":
    raise SystemExit(main())
