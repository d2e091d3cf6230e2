"""Pure building blocks (Flax linen). Imports nothing else of the project but `grid`."""

from .activations import ACTIVATIONS, activation
from .blocks import ConvBNAct, DSConv, ResidualBottleneck
from .conv import Conv, ConvTranspose, DepthwiseConv, PointLinear, shifted_depthwise
from .dcnv3 import DCNv3, deformable_sample
from .fec import FEC, check_fec_filters
from .mobileone import MobileOneBlock, RepDWSeparable, reparameterize_block, reparameterize_tree
from .pillars import PillarFeatureNet, decorate_points, masked_max, scatter_to_bev

__all__ = [
    "ACTIVATIONS", "activation", "ConvBNAct", "DSConv", "ResidualBottleneck", "Conv",
    "ConvTranspose", "DepthwiseConv", "PointLinear", "shifted_depthwise", "FEC",
    "check_fec_filters", "DCNv3", "deformable_sample", "MobileOneBlock", "RepDWSeparable", "reparameterize_block", "reparameterize_tree", "PillarFeatureNet", "decorate_points", "masked_max", "scatter_to_bev",
]
