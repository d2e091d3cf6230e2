"""Profiler: params, GFLOPs (analytic per layer + XLA), memory and latency, as records."""

from .counting import count_gflops, count_params, layer_macs, xla_gflops
from .records import profile, size_record

__all__ = ["count_gflops", "count_params", "layer_macs", "xla_gflops", "profile", "size_record"]
