"""The monodepth network, its post-processing and the jitted predictor, on tiny shapes."""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.core import atomic, checkpoint
from dsfec_jax.models.depth import TINY, MonodepthConfig, MonodepthNet, init_variables, post_process_disparity
from dsfec_jax.modalities.image.depth import MonodepthPredictor, load_depth_predictor, save_depth_weights

DEFAULT_PARAMS = 2_004_264  # MonodepthConfig(): encoder 16-32-64-128-256, kernels 7-5-3-3-3, top 8


@pytest.fixture(scope="module")
def variables():
    return init_variables(TINY, jax.random.key(0))


@pytest.fixture(scope="module")
def forward():
    return jax.jit(MonodepthNet(TINY).apply)


def _images(b=2, seed=0):
    return jnp.asarray(np.random.default_rng(seed).random((b, TINY.height, TINY.width, 3)), jnp.float32)


def test_four_scales_of_two_channels_in_range(variables, forward):
    disps = forward(variables, _images())
    assert [d.shape for d in disps] == [(2, 32 // 2 ** s, 64 // 2 ** s, 2) for s in range(4)]
    for d in disps:
        assert float(d.min()) > 0 and float(d.max()) < 0.3


def test_heads_saturate_at_max_disparity(variables, forward):
    """0.3 * sigmoid: huge biases drive every head to its bounds and never past them."""
    for bias, bound in ((1e4, 0.3), (-1e4, 0.0)):
        params = {k: ({**v, "Conv_0": {**v["Conv_0"], "bias": jnp.full(2, bias)}} if k.startswith("disp") else v)
                  for k, v in variables["params"].items()}
        for d in forward({"params": params}, _images()):
            np.testing.assert_allclose(d, bound, atol=1e-6)


def test_coarser_disparity_feeds_the_next_level(variables):
    """monodepth's udisp: iconv at 1/4, 1/2 and full resolution reads 2 more channels (the
    upsampled disparity) than the upconv and skip give; the coarsest head's level does not."""
    p = variables["params"]
    w = TINY.encoder_widths
    in_channels = {j: p[f"iconv{j}"]["Conv_0"]["kernel"].shape[2] for j in range(4)}
    assert in_channels == {3: w[2] + w[2], 2: w[1] + w[1] + 2, 1: w[0] + w[0] + 2, 0: TINY.top_width + 2}


def test_parameter_count_of_the_default_config_is_pinned():
    shapes = jax.eval_shape(MonodepthNet(MonodepthConfig()).init, jax.random.key(0),
                            jax.ShapeDtypeStruct((1, 128, 224, 3), jnp.float32))
    assert sum(int(np.prod(x.shape)) for x in jax.tree.leaves(shapes)) == DEFAULT_PARAMS


def test_init_is_xavier_uniform_and_seeded():
    a, b = init_variables(TINY, jax.random.key(0)), init_variables(TINY, jax.random.key(1))
    kernel = a["params"]["enc1_a"]["Conv_0"]["kernel"]  # 3x3, 4 -> 8
    limit = np.sqrt(6 / (9 * (4 + 8)))
    assert np.abs(kernel).max() <= limit and np.abs(kernel).max() > 0.8 * limit
    assert not np.any(a["params"]["enc1_a"]["Conv_0"]["bias"])
    jax.tree.map(np.testing.assert_array_equal, a, init_variables(TINY, jax.random.key(0)))
    assert not np.array_equal(kernel, b["params"]["enc1_a"]["Conv_0"]["kernel"])


def test_bad_config_and_input_are_named():
    with pytest.raises(ValueError, match="multiple of 32"):
        MonodepthConfig(height=120)
    with pytest.raises(ValueError, match="at least 4 levels"):
        MonodepthConfig(encoder_widths=(8, 16, 32), encoder_kernels=(3, 3, 3), height=64, width=64)
    with pytest.raises(ValueError, match="multiple of 16"):
        MonodepthNet(TINY).init(jax.random.key(0), jnp.zeros((1, 24, 64, 3)))


def _monodepth_post_process(disp):
    """monodepth_main.py post_process_disparity, line by line, on (2, h, w)."""
    _, h, w = disp.shape
    l_disp = disp[0]
    r_disp = np.fliplr(disp[1])
    m_disp = 0.5 * (l_disp + r_disp)
    l, _ = np.meshgrid(np.linspace(0, 1, w), np.linspace(0, 1, h))
    l_mask = 1.0 - np.clip(20 * (l - 0.05), 0, 1)
    r_mask = np.fliplr(l_mask)
    return r_mask * l_disp + l_mask * r_disp + (1.0 - l_mask - r_mask) * m_disp


def test_post_process_hand_case():
    """Plain map 1, mirror's map 3 (flipped: 3): the mirror's value at the left edge, the plain one
    at the right edge, the mean (2) in the middle, linear ramps 5 % wide between."""
    w = 41  # linspace(0, 1, 41) steps 0.025: columns 0-2 are <= 0.05, the ramp ends at column 4
    out = np.asarray(post_process_disparity(jnp.ones((1, w)), jnp.full((1, w), 3.0)))[0]
    np.testing.assert_allclose(out[:3], 3.0)
    np.testing.assert_allclose(out[3], 2.5)  # l = 0.075: l_mask 0.5 -> 0.5 * 3 + 0.5 * 2
    np.testing.assert_allclose(out[4:-4], 2.0)
    np.testing.assert_allclose(out[-3:], 1.0)


def test_post_process_equals_monodepths_formula():
    disp = np.random.default_rng(0).random((2, 5, 37)).astype(np.float32)
    np.testing.assert_allclose(post_process_disparity(jnp.asarray(disp[0]), jnp.asarray(disp[1])),
                               _monodepth_post_process(disp), rtol=1e-6)


def _frame_image(seed=0):
    return np.random.default_rng(seed).integers(0, 256, (36, 64, 3), dtype=np.uint8)


def test_predictor_shape_and_mirror_symmetry(variables):
    """Post-processing is exactly mirror-equivariant: P(mirror I) = mirror P(I) (the masks swap under
    a flip); the plain map is not."""
    image = _frame_image()
    pp = MonodepthPredictor(TINY, variables)
    disp = pp(image)
    assert disp.shape == (36, 64) and disp.dtype == np.float32
    np.testing.assert_allclose(pp(image[:, ::-1]), disp[:, ::-1], rtol=1e-5, atol=1e-7)
    plain = MonodepthPredictor(TINY, variables, post_process=False)
    assert np.abs(plain(image[:, ::-1]) - plain(image)[:, ::-1]).max() > 1e-4


def test_predictor_blends_the_network_maps(variables, forward):
    image = _frame_image(1)
    pp = MonodepthPredictor(TINY, variables)
    x = pp.network_input(image)
    both = forward(variables, jnp.concatenate([x, x[:, :, ::-1]]))[0][..., 0]
    np.testing.assert_allclose(pp.network_disparity(image), _monodepth_post_process(np.asarray(both)), rtol=1e-5)


def test_weights_round_trip_and_missing_config(variables, tmp_path):
    path = tmp_path / "w.msgpack"
    save_depth_weights(path, TINY, variables, {"seed": 0}, step=3)
    assert zoo.training_record(path) == {"seed": 0, "config": json.loads(json.dumps(TINY.to_dict()))}
    loaded = load_depth_predictor(path)
    assert loaded.config == TINY
    np.testing.assert_array_equal(loaded(_frame_image()), MonodepthPredictor(TINY, variables)(_frame_image()))
    manifest = path.with_name("w.msgpack.json")
    atomic.write_text(manifest, manifest.read_text().replace('"config"', '"other"'))
    with pytest.raises(ValueError, match="no 'config'"):
        load_depth_predictor(path)
    other = dataclasses.replace(TINY, top_width=6)
    save_depth_weights(path, other, variables)
    with pytest.raises(ValueError, match="shape"):
        load_depth_predictor(path)


def _first_format(path, config, variables, **provenance):
    """Weights as the depth network wrote them before it joined the zoo (modalities/image/depth.py at
    3487237: save_depth_weights): {'params'}, the manifest's "format" and whole "config" at its top level."""
    checkpoint.save(path, {"params": variables["params"]},
                    {"format": "dsfec_jax.monodepth", "config": config.to_dict(), "step": 3, **provenance})


def test_weights_of_the_first_format_load_and_convert_unchanged(variables, tmp_path):
    from dsfec_jax.data.camera.street import StreetConfig
    from dsfec_jax.modalities.image.ship_depth import convert_depth_weights

    old, new = tmp_path / "old.msgpack", tmp_path / "new.msgpack"
    wide = dataclasses.replace(TINY, width=96)  # the config comes from the file, not from its name
    _first_format(old, wide, variables, seed=4, train_command="dsfec depth train x", ship_command="dsfec depth ship x",
                  source="x/monodepth.msgpack", init_chain=[{"path": "w", "step": 1}])
    image = _frame_image()
    expected = MonodepthPredictor(wide, variables)(image)
    loaded = load_depth_predictor(old)
    assert loaded.config == wide
    np.testing.assert_array_equal(loaded(image), expected)
    manifest = convert_depth_weights(old, new, "dsfec depth convert --weights old", frames=1,
                                     street_config=StreetConfig(width=64))
    assert manifest["sha256"] == checkpoint.read_manifest(old)["sha256"]  # the same bytes
    assert (manifest["model"], manifest["step"], manifest["source_checkpoint"]) == ("monodepth_tiny", 3, "x/monodepth.msgpack")
    assert manifest["ship_command"] == "dsfec depth ship x" and manifest["convert_command"] == "dsfec depth convert --weights old"
    training = manifest["training"]
    assert (training["command"], training["seed"], training["init_chain"]) == ("dsfec depth train x", 4, [{"path": "w", "step": 1}])
    assert manifest["measured"]["test"]["frames"] == 1 and manifest["versions"]["jax"]
    np.testing.assert_array_equal(load_depth_predictor(new)(image), expected)
    with pytest.raises(ValueError, match="already in the zoo's layout"):
        convert_depth_weights(new, tmp_path / "again.msgpack", "")
