"""Detector families: a frozen config dataclass + the network assembly per family."""

from .dsfec import DSFECConfig, DSFECNet

__all__ = ["DSFECConfig", "DSFECNet"]
