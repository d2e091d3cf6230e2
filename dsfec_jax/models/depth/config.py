"""Every knob of the monodepth-style disparity network (Godard et al. 2017, mrharicot/monodepth).

The network maps one left image to disparities at 4 scales (full, 1/2, 1/4, 1/8 resolution), 2
channels each: the left-view disparity (channel 0) and the right-view disparity (channel 1), as a
fraction of the image width, d = `max_disparity` * sigmoid (monodepth: 0.3). A fraction of the
width does not depend on the resolution it is read at: disparity in pixels = d * W for an image
W pixels wide, whatever size the network ran at.

Encoder: monodepth's VGG layout, one `conv_block` per entry of `encoder_widths` (a k x k conv at
stride 1, then one at stride 2, ELU), so the deepest map is at 1/2**len(encoder_widths).
Decoder: at every scale from the deepest up, a nearest x2 upsample + 3x3 conv ("upconv"), concatenated
with the encoder map of that scale and, from 1/4 resolution on, with the upsampled disparity of
the coarser scale, then a 3x3 conv ("iconv"); its width is the encoder width of that scale
(`top_width` at full resolution), as monodepth's decoder mirrors its encoder (512 ... 32, then 16).

Default size, chosen for this project's 2-core CPU and the street benchmark (416 x 234 frames of a
120-degree camera, fx = 120 px at 416 wide):
- input 128 x 224 (H x W): the frame's aspect (1.78; 224 / 128 = 1.75) at 0.54 of its width, a
  multiple of 32 on both sides (five stride-2 levels). The camera is very wide, so things are
  small: 40 m away a car (1.8 x 1.5 m) is 2.9 x 2.4 px at 224 wide (5.4 x 4.5 in the 416 frame), a
  pedestrian (0.55 x 1.72 m) 0.9 x 2.8 px, and the disparity fx * B / Z is 0.87 px (1.6 at 416):
  still inside the network's reach, since the bilinear warp makes the loss see sub-pixel
  disparities, but 40 m is about the limit. 160 x 288 (1.1 px at 40 m) costs twice the time per
  step on this CPU (measured: docs/edge-and-map-service.md), i.e.
  half the training in the same half hour. monodepth used 256 x 512 on KITTI (fx = 721 px at 1242:
  3.1 px of disparity at 40 m at 512 wide).
- encoder widths 16-32-64-128-256 (monodepth's VGG: 32-64-128-256-512-512-512 over 7 levels) and
  kernels 7-5-3-3-3 as monodepth's first five: 2.0 M parameters (monodepth's VGG: ~31 M) and
  ~1.5 GFLOPs per image; half an hour on one core trains ~800 batch-8 steps. Five levels, not
  seven: 128 / 2**5 = 4, and a deeper encoder would need padding. The measured figures are in
  docs/edge-and-map-service.md.
"""

from __future__ import annotations

import dataclasses

NUM_SCALES = 4          # disparity heads: full, 1/2, 1/4, 1/8 resolution (monodepth's disp1..disp4)
DISPARITY_CHANNELS = 2  # left-view disparity, right-view disparity


@dataclasses.dataclass(frozen=True)
class MonodepthConfig:
    name: str = "monodepth_street"
    height: int = 128                      # network input, pixels (module docstring)
    width: int = 224
    encoder_widths: tuple[int, ...] = (16, 32, 64, 128, 256)  # one conv_block (stride 2) each
    encoder_kernels: tuple[int, ...] = (7, 5, 3, 3, 3)        # monodepth's VGG: 7, 5, then 3
    top_width: int = 8                     # decoder width at full resolution (monodepth: 16 after 32)
    max_disparity: float = 0.3             # d = max_disparity * sigmoid(conv), a fraction of the width

    def __post_init__(self):
        levels = len(self.encoder_widths)
        if levels < NUM_SCALES or len(self.encoder_kernels) != levels:
            raise ValueError(f"MonodepthConfig {self.name!r}: encoder_widths {self.encoder_widths} needs at least "
                             f"{NUM_SCALES} levels (the disparity scales) and one kernel each, got encoder_kernels "
                             f"{self.encoder_kernels}")
        if min(self.encoder_widths) < 1 or self.top_width < 1 or min(self.encoder_kernels) < 1:
            raise ValueError(f"MonodepthConfig {self.name!r}: widths and kernels must be positive")
        if self.height % self.stride or self.width % self.stride or self.height < 1 or self.width < 1:
            raise ValueError(f"MonodepthConfig {self.name!r}: input {self.height} x {self.width} must be a positive "
                             f"multiple of {self.stride} on both sides ({levels} stride-2 levels)")
        if not 0 < self.max_disparity <= 1:
            raise ValueError(f"MonodepthConfig {self.name!r}: max_disparity={self.max_disparity} must be in (0, 1]")

    @property
    def stride(self) -> int:
        """The deepest map's stride: the input sides must be multiples of it."""
        return 2 ** len(self.encoder_widths)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "MonodepthConfig":
        """The config a checkpoint manifest recorded (JSON lists back to tuples)."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"MonodepthConfig: unknown fields {unknown}; expected some of {sorted(known)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


TINY = MonodepthConfig(name="monodepth_tiny", height=32, width=64, encoder_widths=(4, 8, 8, 16),
                       encoder_kernels=(3, 3, 3, 3), top_width=4)  # tests and smoke runs
