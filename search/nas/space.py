"""A one-shot NAS search space as data: named choice blocks, each with its options.

A subnet is one option per block, held as a tuple of option indices (its genes), so it hashes,
compares and serialises the same way in every strategy. The space counts its subnets, samples
them uniformly (SPOS's single-path sampling and the evolution's random candidates), mutates and
crosses them over (the YOLOv8n-Adapter paper, Sec. 3.4), and turns a subnet into overrides of an
ordinary zoo config: that config, trained stand-alone, is the network the subnet stands for.

Mutation follows megvii's SinglePathOneShot (`src/Search/search.py`): each gene is redrawn
uniformly over all of its options with probability `prob` (so a redraw may keep the option);
crossover takes each gene from one of the two parents with probability 1/2. Every random step
takes a numpy Generator, so a seeded search draws the same subnets again.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Sequence

import numpy as np

Genes = tuple[int, ...]
KINDS = ("width", "categorical", "depth")


class SpaceError(ValueError):
    pass


@dataclasses.dataclass(frozen=True)
class Choice:
    """One choice block: `name` (unique in its space), its `options` (width ratios, fusion ids,
    block counts) and their `kind` (how reports and supernets read them)."""

    name: str
    options: tuple
    kind: str = "width"

    def __post_init__(self):
        if len(self.options) < 1:
            raise SpaceError(f"choice {self.name!r}: expected at least one option")
        if len(set(self.options)) != len(self.options):
            raise SpaceError(f"choice {self.name!r}: options repeat: {self.options}")
        if self.kind not in KINDS:
            raise SpaceError(f"choice {self.name!r}: kind {self.kind!r}, expected one of {KINDS}")


@dataclasses.dataclass(frozen=True)
class SearchSpace:
    """Choice blocks over a zoo model `base`; `to_overrides(choices)` maps a subnet's
    {block name: option} to the base config's overrides that build it stand-alone."""

    name: str
    base: str
    choices: tuple[Choice, ...]
    to_overrides: Callable[[dict], dict] = dataclasses.field(compare=False)
    description: str = ""
    base_choices: dict = dataclasses.field(default_factory=dict, compare=False)  # the base model's, where not largest
    # how a NAS run trains its supernet and scores its subnets (a search.nas.engines.EngineKind;
    # None for a space that is only sampled, never run)
    engine: Any = dataclasses.field(default=None, compare=False)

    def __post_init__(self):
        names = [c.name for c in self.choices]
        if len(set(names)) != len(names):
            raise SpaceError(f"space {self.name!r}: choice names repeat: {names}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.choices)

    def size(self) -> int:
        """How many distinct subnets the space holds (the product of the option counts)."""
        return math.prod(len(c.options) for c in self.choices)

    def check(self, genes: Sequence[int]) -> Genes:
        """`genes` as a tuple of ints, or a SpaceError naming the block that is out of range."""
        genes = tuple(int(g) for g in genes)
        if len(genes) != len(self.choices):
            raise SpaceError(f"space {self.name!r}: expected {len(self.choices)} genes, got {len(genes)}")
        for g, c in zip(genes, self.choices):
            if not 0 <= g < len(c.options):
                raise SpaceError(f"space {self.name!r}: gene of {c.name!r} is {g}, expected 0..{len(c.options) - 1}")
        return genes

    def sample(self, rng: np.random.Generator) -> Genes:
        """A subnet drawn uniformly: every block's option independently and uniformly."""
        return tuple(int(rng.integers(len(c.options))) for c in self.choices)

    def mutate(self, genes: Genes, rng: np.random.Generator, prob: float) -> Genes:
        """Each gene redrawn uniformly over its options with probability `prob`."""
        redraw = rng.random(len(genes)) < prob
        fresh = self.sample(rng)
        return tuple(f if r else g for g, f, r in zip(genes, fresh, redraw))

    def crossover(self, a: Genes, b: Genes, rng: np.random.Generator) -> Genes:
        """Each gene from `a` or `b`, equally likely."""
        take_b = rng.random(len(a)) < 0.5
        return tuple(y if t else x for x, y, t in zip(a, b, take_b))

    def decode(self, genes: Sequence[int]) -> dict:
        """{block name: chosen option}."""
        return {c.name: c.options[g] for c, g in zip(self.choices, self.check(genes))}

    def encode(self, choices: dict) -> Genes:
        """The genes of {block name: option} (every block named, every option one of its own)."""
        missing = set(self.names) - set(choices)
        if missing:
            raise SpaceError(f"space {self.name!r}: no option given for {sorted(missing)}")
        genes = []
        for c in self.choices:
            if choices[c.name] not in c.options:
                raise SpaceError(f"space {self.name!r}: {c.name}={choices[c.name]!r} is not one of {c.options}")
            genes.append(c.options.index(choices[c.name]))
        return tuple(genes)

    def overrides(self, genes: Sequence[int]) -> dict:
        """The zoo config overrides of the subnet: `zoo.create(space.base, **overrides)`."""
        return self.to_overrides(self.decode(genes))

    def largest(self) -> Genes:
        """Every block at its last option (by convention the widest / deepest)."""
        return tuple(len(c.options) - 1 for c in self.choices)

    def base_genes(self) -> Genes:
        """The subnet that is the base model itself (the report's hand-designed reference)."""
        return self.encode({**self.decode(self.largest()), **self.base_choices})

    def smallest(self) -> Genes:
        return (0,) * len(self.choices)


def key(genes: Sequence[int]) -> str:
    """A subnet's journal key: its genes, e.g. '1-0-3-2'."""
    return "-".join(str(int(g)) for g in genes)


def from_key(text: str) -> Genes:
    try:
        return tuple(int(g) for g in text.split("-"))
    except ValueError as err:
        raise SpaceError(f"subnet key {text!r}: expected genes joined by '-', e.g. '1-0-3'") from err
