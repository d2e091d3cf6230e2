import atexit
import shutil
import tempfile

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.core.grid import Grid

# Tests rebuild identical networks many times: a per-session persistent compilation cache makes
# the second compile of the same program a cache hit. It is removed when the process exits (each
# xdist worker has its own), since it grows to ~160 MB a session.
_CACHE_DIR = tempfile.mkdtemp(prefix="dsfec-jax-cache-")
atexit.register(shutil.rmtree, _CACHE_DIR, ignore_errors=True)
jax.config.update("jax_compilation_cache_dir", _CACHE_DIR)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

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
