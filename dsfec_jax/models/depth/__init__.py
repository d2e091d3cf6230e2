"""The monodepth-style disparity network (Godard et al. 2017): config, net, post-processing.

    from dsfec_jax.models.depth import MonodepthConfig, MonodepthNet, init_variables
    disps = MonodepthNet(cfg).apply(variables, images)  # 4 scales, finest first, (B, h, w, 2)

Training (the losses, the loop) lives in dsfec_jax.models.depth.loss / fit_depth; the predictor in
dsfec_jax.modalities.image.depth.
"""

from .config import DISPARITY_CHANNELS, NUM_SCALES, TINY, MonodepthConfig
from .net import MonodepthNet, count_params, init_variables
from .postprocess import post_process_disparity, ramp_masks

__all__ = ["DISPARITY_CHANNELS", "NUM_SCALES", "TINY", "MonodepthConfig", "MonodepthNet", "count_params",
           "init_variables", "post_process_disparity", "ramp_masks"]
