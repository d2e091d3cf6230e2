import atexit
import os
import shutil
import tempfile

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.core.grid import Grid

# Tests rebuild identical networks many times: a persistent compilation cache makes the second
# compile of the same program a cache hit. The first process to load this file (pytest itself,
# or xdist's controller, which loads it before it starts its workers) makes the folder, names it
# in the environment the workers inherit, and removes it at exit; so both workers of a run share
# one cache, and a program one of them compiled is a hit on the other. It grows to a few hundred
# MB a session.
_CACHE_ENV = "DSFEC_TEST_COMPILATION_CACHE"
if _CACHE_ENV not in os.environ:
    os.environ[_CACHE_ENV] = tempfile.mkdtemp(prefix="dsfec-jax-cache-")
    atexit.register(shutil.rmtree, os.environ[_CACHE_ENV], ignore_errors=True)
_CACHE_DIR = os.environ[_CACHE_ENV]
jax.config.update("jax_compilation_cache_dir", _CACHE_DIR)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
# a size limit turns on the cache's file lock (filelock), so one worker never reads an entry the
# other is still writing
jax.config.update("jax_compilation_cache_max_size", 8 << 30)

# The suite's programs run on toy shapes, so compiling them costs far more than running them:
# LLVM's optimisation of the generated loops is skipped (the XLA graph passes all still run, and
# dots and convolutions call the same library kernels). Measured on `.ci/run`: docs/setup-and-tests.md,
# "The test suite". Set before the first computation, when XLA reads its flags.
if "--xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=0").strip()

TINY_GRID = Grid(x_range=(0.0, 16.0), y_range=(-8.0, 8.0), z_range=(-2.5, 2.5), cell=0.5)  # 32 x 32


def tiny(name: str, /, **overrides):
    """A registered variant on a 32x32 grid with few pillar slots: same layers, cheap to compile."""
    overrides = {"grid": TINY_GRID, "max_pillars": 96, "max_points": 4, **overrides}
    return zoo.create(name, **overrides)


@pytest.fixture
def float64():
    """Whole networks in float64: a 32 x 32 toy batch leaves batch norm nearly degenerate (few
    occupied cells), which turns float32 rounding into ~1e-3 differences between any two
    summation orders (the baseline's, measured); in float64 two formulations agree to ~1e-13."""
    jax.config.update("jax_enable_x64", True)
    yield
    jax.config.update("jax_enable_x64", False)


def as_float64(tree):
    """float32 leaves (parameters, batches) as float64, the rest unchanged."""
    return jax.tree.map(lambda a: a.astype(jnp.float64) if getattr(a, "dtype", None) == jnp.float32 else a, tree)


def random_fill(shapes, seed: int, scale_range=(0.0, 1.0), var_range=(0.5, 2.0), zeros=()) -> dict:
    """Random weights and non-trivial BN statistics for a tree of variable shapes; leaves named in
    `zeros` stay 0 (parameters whose initial value is the point, e.g. the Adapter's alpha)."""
    rng = np.random.default_rng(seed)

    def fill(path, leaf):
        name = path[-1].key
        if name in zeros:
            return jnp.zeros(leaf.shape, leaf.dtype)
        if name == "var":
            return jnp.asarray(rng.uniform(*var_range, leaf.shape), leaf.dtype)
        if name == "scale":
            return jnp.asarray(rng.uniform(*scale_range, leaf.shape), leaf.dtype)
        fan_in = int(np.prod(leaf.shape[:-1])) if len(leaf.shape) > 1 else 4
        return jnp.asarray(rng.normal(0, fan_in**-0.5, leaf.shape), leaf.dtype)

    return jax.tree_util.tree_map_with_path(fill, shapes)


def random_variables(det, seed: int) -> dict:
    """Random weights and non-trivial BN statistics without compiling `init` (the shapes come
    from eval_shape), so fusion is tested on more than identity statistics."""
    return random_fill(jax.eval_shape(det.init, jax.random.key(0)), seed)


def random_init(init):
    """`init` (zoo.Detector.init's signature) without compiling it: its tree's shapes from
    eval_shape, filled with small uniform weights and positive BN variances. Compiling `init`
    traces and compiles the whole forward pass (seconds to tens of seconds for a YOLO or a
    supernet); tests of a pipeline's wiring that train, score or ship whatever weights they get
    use this (the real init is tested on its own)."""

    def quick_init(self, rng):
        gen = np.random.default_rng(0)

        def fill(path, leaf):
            low, high = (0.5, 1.5) if path[-1].key == "var" else (-0.1, 0.1)
            return jnp.asarray(gen.uniform(low, high, leaf.shape), leaf.dtype)

        return jax.tree_util.tree_map_with_path(fill, jax.eval_shape(lambda r: init(self, r), rng))

    return quick_init


@pytest.fixture
def uncompiled_init(monkeypatch):
    """Every zoo.Detector's `init` in this test as random_init's (nothing compiled)."""
    monkeypatch.setattr(zoo.Detector, "init", random_init(zoo.Detector.init))


@pytest.fixture
def tiny_detector():
    return tiny


def shared_data_dir():
    """Real sample data (non-commercial licences: read by path, never copied into the repo)."""
    import os
    from pathlib import Path

    default = Path(__file__).resolve().parents[1].parent / "shared" / "data"
    return Path(os.environ.get("DSFEC_DATA", default))


@pytest.fixture
def shared_data():
    path = shared_data_dir()
    if not path.is_dir():
        pytest.fail(f"real sample data not found at {path}; set DSFEC_DATA")
    return path
