"""`python -m dsfec_jax.deploy.bench ...`: one bench worker, launched by `workers.run` once per
thread count (users run `dsfec bench`)."""

from .workers import main

if __name__ == "__main__":
    raise SystemExit(main())
