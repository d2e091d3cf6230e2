"""The FEC module (DSFEC §3.1): per-point feature enhancement then compression."""

from __future__ import annotations

import flax.linen as nn

from .activations import activation
from .conv import Kernels, PointLinear


def check_fec_filters(filters: tuple[int, ...]) -> None:
    """The paper's rule f1 < f2, f2 > f3, f1 >= f3 (enhance, then compress no wider than f1)."""
    if len(filters) != 3 or any(int(f) <= 0 for f in filters):
        raise ValueError(f"FEC filters={filters}: expected three positive widths (f1, f2, f3)")
    f1, f2, f3 = filters
    broken = [rule for rule, ok in (("f1 < f2", f1 < f2), ("f2 > f3", f2 > f3), ("f1 >= f3", f1 >= f3)) if not ok]
    if broken:
        raise ValueError(
            f"FEC filters (f1, f2, f3)=({f1}, {f2}, {f3}) break the rule {', '.join(broken)} "
            "(DSFEC requires f1 < f2, f2 > f3, f1 >= f3)"
        )


class FEC(nn.Module):
    """Three per-point 1x1 convs with biases and no batch norm (BN hurt in the paper)."""

    filters: tuple[int, int, int] = (32, 128, 12)
    act: str = "relu"
    kernels: Kernels = "auto"

    def setup(self):
        check_fec_filters(self.filters)
        self.layers = [PointLinear(f, kernels=self.kernels, name=f"conv{i + 1}") for i, f in enumerate(self.filters)]

    def __call__(self, x_BxPxNxD, mask_BxPxN=None, train: bool = False):
        act = activation(self.act)
        for layer in self.layers:
            x_BxPxNxD = act(layer(x_BxPxNxD))
        return x_BxPxNxD
