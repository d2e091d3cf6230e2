"""Detector families: a frozen config dataclass + the network assembly per family."""

from .dsfec import DSFECConfig, DSFECNet
from .radarnext import RadarNeXtConfig, RadarNeXtNet

__all__ = ["DSFECConfig", "DSFECNet", "RadarNeXtConfig", "RadarNeXtNet"]
