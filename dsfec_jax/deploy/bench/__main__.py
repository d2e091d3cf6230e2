"""`python -m dsfec_jax.deploy.bench ...`: one bench worker, launched by `workers.run` once per
thread count (users run `dsfec bench`). An entry point: it looks up each model's modality and hands
its chains to the modality-free worker."""

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from ...core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from ...modalities.registry import modality_of
from .workers import main


def chains_of(name: str):
    """The bench chains of model `name`'s modality."""
    return modality_of(name).bench_chains


if __name__ == "__main__":
    raise SystemExit(main(chains_of))
