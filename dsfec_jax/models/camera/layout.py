"""The fixed layout every camera YOLOv3 detector shares: its one input, five backbone stages and
three output strides. A leaf: config.py and the net's modules both read it, and config.py imports
the net (to build it), so the net never imports config.py."""

INPUT = "image"  # the one input: (B, H, W, 3) float32 in [0, 1], H and W multiples of 32
STAGES = 5  # backbone stages, at strides 2, 4, 8, 16, 32
STRIDES = (8, 16, 32)  # the output maps' strides
