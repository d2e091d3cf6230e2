"""RadarNeXt family: sizes against the paper, fused == unfused, shapes and config errors."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.core.grid import Grid
from dsfec_jax.models.radarnext.center_head import CenterHead
from dsfec_jax.profile import counting
from conftest import random_variables

RADARNEXT = [n for n in zoo.available("radarnext") if not n.endswith("_tj4d")]  # TJ4D: same layers
TINY = dict(grid=Grid((0.0, 5.12), (-2.56, 2.56), (-3.0, 2.0), 0.16), max_pillars=128)  # 32 x 32


def deployed_params(name: str, **overrides) -> int:
    det = zoo.create(name, **overrides)
    variables = jax.eval_shape(det.init, jax.random.key(0))
    fused_det, fused = zoo.deploy(det, jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), variables),
                                  fold_batch_norm=False)
    return counting.count_params(fused)["total"]


def test_all_six_variants_are_registered():
    assert sorted(RADARNEXT) == sorted(f"radarnext_{n}{d}" for n in ("fpn", "pan", "mdfen") for d in ("", "_dense"))


def test_tj4d_variants_read_tj4d_frames_with_four_classes(shared_data):
    from dsfec_jax.data.points.pillarize import PillarSpec, pillarize, select_columns
    from dsfec_jax.data.points.sources import load_frames

    frame = load_frames(f"tj4d:{shared_data / 'tj4dradset' / 'Sample'}", "val", 1, features="native")[0]
    for neck in ("fpn", "pan", "mdfen"):
        cfg = zoo.config(f"radarnext_{neck}_tj4d")
        assert cfg.grid.shape == (432, 432) and cfg.classes[-1] == "truck" and cfg.neck == neck
        tensors, _ = pillarize(select_columns(frame, cfg.point_features), PillarSpec.of(cfg))
        assert tensors["points"].shape[-1] == 8 and tensors["mask"].any()
    vod = deployed_params("radarnext_fpn")
    # 8 columns (+ 6 offsets) in the pillar net's linear layer; one more 3x3 heatmap output channel
    assert deployed_params("radarnext_fpn_tj4d") - vod == 64 + (3 * 3 * 64 + 1)


# Counted by us on the public RadarNeXt code (github Pay246-git468/RadarNeXt, commit 72676df), re-parameterized
# (k = 1, no corner head): 1,579,832 (MDFEN) and 1,531,340 (PAN), the paper's 1.580M / 1.531M; FPN 1.051M there.
@pytest.mark.parametrize("name,expected", [("radarnext_mdfen", 1_579_832), ("radarnext_pan", 1_531_340),
                                           ("radarnext_fpn", 1_051_340), ("radarnext_pan_dense", 5_336_716),
                                           ("radarnext_mdfen_dense", 5_385_208)])
def test_deployed_parameter_counts_match_the_public_code(name, expected):
    assert deployed_params(name) == expected


# Table III: a DCNv3 over C channels adds 2C^2 + 122C + 108 parameters to the PAN's 1,531,340.
@pytest.mark.parametrize("positions,paper_m", [((1,), 1.694), ((2,), 1.694), ((5,), 1.547), ((1, 2, 4), 1.905)])
def test_dcn_positions_reproduce_table_iii_counts(positions, paper_m):
    assert round(deployed_params("radarnext_mdfen", dcn_positions=positions) / 1e6, 3) == paper_m


# Every neck x backbone; a shallower (2, 2, 2) backbone keeps the test fast and still has, in
# every stage, a strided layer (2 branches) and an identity layer (3 branches).
@pytest.mark.parametrize("name", RADARNEXT)
def test_fused_equals_unfused_in_eval_mode(name):
    det = zoo.create(name, layer_nums=(2, 2, 2), **TINY)
    variables = random_variables(det, 1)
    inputs = det.dummy_inputs(1)
    fused_det, fused = zoo.deploy(det, variables)
    assert fused_det.config.deploy and not fused_det.config.corner_head
    out = jax.jit(det.apply)(variables, inputs)
    fused_out = jax.jit(fused_det.apply)(fused, inputs)
    assert set(out) - set(fused_out) == {"corner_hm"}
    for key, value in fused_out.items():
        assert value.shape == out[key].shape == (1, 16, 16, value.shape[-1])  # H/2 of the 32 x 32 grid
        assert float(jnp.abs(value).max()) > 1e-3, f"{name}: {key} is all zeros"
        np.testing.assert_allclose(value, out[key], atol=1e-5, rtol=1e-5, err_msg=f"{name}: {key}")
    if det.config.backbone == "rep_dwc":  # a MobileOne block really was fused: no branch BN left
        layer = fused["params"]["backbone_net"]["stage1_layer1"]["dw"]
        assert set(layer) == {"kernel", "bias"} and "backbone_net" not in fused["batch_stats"]


def test_head_outputs_and_heatmap_prior():
    det = zoo.create("radarnext_pan", layer_nums=(1, 1, 1), **TINY)
    out = jax.jit(det.apply)(random_variables(det, 0), det.dummy_inputs(1, occupancy=0.0))
    channels = {k: v.shape[-1] for k, v in out.items()}
    assert channels == {"reg": 2, "height": 1, "dim": 3, "rot": 2, "iou": 1, "hm": 3, "corner_hm": 1}
    head = CenterHead(3).init(jax.random.key(0), jnp.zeros((1, 4, 4, 384)))
    np.testing.assert_allclose(head["params"]["hm_out"]["bias"], -2.19)
    np.testing.assert_allclose(head["params"]["corner_hm_out"]["bias"], -2.19)
    np.testing.assert_allclose(head["params"]["reg_out"]["bias"], 0.0)


@pytest.mark.parametrize("overrides,field", [
    (dict(neck="mdfen", dcn_positions=()), "dcn_positions"),
    (dict(neck="pan", dcn_positions=(4,)), "dcn_positions"),
    (dict(dcn_positions=(6,)), "dcn_positions"),
    (dict(neck="bifpn"), "neck"),
    (dict(backbone="resnet"), "backbone"),
    (dict(layer_nums=(3, 0, 5)), "layer_nums"),
])
def test_invalid_configs_name_the_field(overrides, field):
    with pytest.raises(ValueError, match=field):
        zoo.create("radarnext_mdfen", **overrides)


def test_non_reparameterizable_families_deploy_unchanged():
    det = zoo.create("dsfec_s")
    same, variables = zoo.deploy(det, {"params": {}}, fold_batch_norm=False)
    assert same is det and variables == {"params": {}}


def test_dense_backbone_has_no_mobileone_blocks():
    det = zoo.create("radarnext_fpn_dense", **TINY)
    params = jax.eval_shape(det.init, jax.random.key(0))["params"]["backbone_net"]
    assert sorted(params)[:2] == ["stage1_conv0", "stage1_conv1"] and len(params) == 3 + 5 + 5 + 3
    assert jnp.ndim(params["stage1_conv0"]["conv"]["kernel"]) == 4


def test_origin_input_equals_a_detector_built_on_that_window():
    """Training windows pass their origin as an input instead of compiling one network each."""
    window = Grid((2.56, 7.68), (-1.28, 3.84), (-3.0, 2.0), 0.16)  # the TINY shape, shifted
    base = zoo.create("radarnext_fpn", layer_nums=(1, 1, 1), **TINY)
    on_window = zoo.create("radarnext_fpn", layer_nums=(1, 1, 1), grid=window, max_pillars=128)
    variables = random_variables(base, 3)
    inputs = on_window.dummy_inputs(1)
    want = jax.jit(on_window.apply)(variables, inputs)
    got = jax.jit(base.apply)(variables, {**inputs, "origin": jnp.array([[2.56, -1.28]])})
    shifted = jax.jit(base.apply)(variables, inputs)  # without the origin: the base grid's offsets
    np.testing.assert_allclose(got["hm"], want["hm"], atol=1e-5)
    assert float(jnp.abs(shifted["hm"] - want["hm"]).max()) > 1e-4
