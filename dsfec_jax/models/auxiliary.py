"""What an auxiliary model is, as one record: a registered network that is not a detector (the
monocular depth network), named, built and loaded through the zoo like a detector's variants.

A detector family (`models/family.py`) carries what training, scoring, export and search need;
an auxiliary model only what the zoo needs to name, build and load it: its config class and
variants, its network, fresh variables, and the collections its weights files hold. Its own
training and prediction live with its modality (the depth network's: modalities/image/).
`zoo.AUXILIARIES` lists the records; each lives beside its network (`models/<name>/auxiliary.py`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping


@dataclasses.dataclass(frozen=True)
class Auxiliary:
    """A registered non-detector network.

    `name`: the record's key in zoo.AUXILIARIES ('depth'); `task`: what it predicts, in words.
    `config_class`, `variants` (name -> frozen config; the shipped weights are named after their
    variant, as a detector's); `build(cfg)` -> the flax module; `init(cfg, rng)` -> fresh variables;
    `dummy_inputs(cfg, batch_size)` -> the module's positional inputs; `config_from_dict(d)` -> the
    config a weights file's training record holds (JSON lists back to tuples); `collections`: the
    variables its weights files hold. `first_format_training(manifest)`: for a model whose weights
    had a manifest layout of their own before it joined the zoo, such a manifest's training record
    in the zoo's layout (None for any other manifest), so that old files load through the one loader."""

    name: str
    task: str
    config_class: type
    variants: Mapping[str, Any]
    build: Callable[[Any], Any]
    init: Callable[[Any, Any], dict]
    dummy_inputs: Callable[[Any, int], tuple]
    config_from_dict: Callable[[dict], Any]
    collections: tuple[str, ...] = ("params",)
    first_format_training: Callable[[dict], dict | None] | None = None

    def __post_init__(self):
        wrong = [n for n, cfg in self.variants.items() if not isinstance(cfg, self.config_class)]
        if wrong:
            raise TypeError(f"auxiliary model {self.name!r}: variants {wrong} are not {self.config_class.__name__}")
        misnamed = [n for n, cfg in self.variants.items() if getattr(cfg, "name", n) != n]
        if misnamed:
            raise ValueError(f"auxiliary model {self.name!r}: variants {misnamed} have a config of another name")
