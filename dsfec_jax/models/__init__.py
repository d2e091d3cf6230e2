"""Detector families: a frozen config dataclass + the network assembly per family."""

from .dsfec.net import DSFECConfig, DSFECNet
from .radarnext.net import RadarNeXtConfig, RadarNeXtNet

__all__ = ["DSFECConfig", "DSFECNet", "RadarNeXtConfig", "RadarNeXtNet"]
