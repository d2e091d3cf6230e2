"""The model zoo: the registry of named variants, their configs, detectors and weights files.

    >>> from dsfec_jax import zoo
    >>> zoo.available("dsfec")
    ['baseline', 'dsfec_l', 'dsfec_m', 'dsfec_s']
    >>> det = zoo.create("dsfec_s", stem_filters=16)
    >>> variables = det.init(jax.random.key(0))
    >>> heads = det.apply(variables, det.dummy_inputs(1))

It sits above `models/` and imports nothing above them (models, core): a ready predictor of
trained weights is `dsfec_jax.api.load`, which asks the model's modality for it.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import jax

from .models.camera.family import FAMILY as CAMERA
from .models.dsfec.family import FAMILY as DSFEC
from .models.family import MODALITIES, Family
from .models.radarnext.family import FAMILY as RADARNEXT
from .models.yolo_rd.family import FAMILY as YOLO_RD

# The registry of families: a new family is its folder under models/ plus one entry here.
FAMILIES: dict[str, Family] = {f.name: f for f in (DSFEC, RADARNEXT, YOLO_RD, CAMERA)}
REGISTRY: dict[str, Any] = {name: cfg for f in FAMILIES.values() for name, cfg in f.variants.items()}


def available(family: str | None = None, modality: str | None = None) -> list[str]:
    """Names of the registered variants, optionally of one family (a key of FAMILIES) or of one
    modality ('points': the point-cloud families; 'rd': range-Doppler maps; 'image': camera images)."""
    if family is not None and family not in FAMILIES:
        raise KeyError(f"unknown family {family!r}; families: {sorted(FAMILIES)}")
    if modality is not None and modality not in MODALITIES:
        raise KeyError(f"unknown modality {modality!r}; modalities: {MODALITIES}")
    names = REGISTRY if family is None else FAMILIES[family].variants
    return sorted(n for n in names if modality is None or family_of(n).modality == modality)


def family_of(cfg_or_name) -> Family:
    """The Family record of a config (or of a registered variant's name)."""
    cfg = config(cfg_or_name) if isinstance(cfg_or_name, str) else cfg_or_name
    for family in FAMILIES.values():
        if type(cfg) is family.config_class:
            return family
    raise TypeError(f"{type(cfg).__name__} belongs to no registered family; families: {sorted(FAMILIES)}")


def config(name: str, /, **overrides):
    """The frozen config of `name` with `overrides` applied (validated)."""
    if name not in REGISTRY:
        raise KeyError(f"unknown model {name!r}; available: {available()}")
    base = REGISTRY[name]
    fields = {f.name for f in dataclasses.fields(base)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise TypeError(f"unknown field(s) {unknown} for {name!r}; valid fields: {sorted(fields)}")
    overrides = {k: tuple(v) if isinstance(v, list) else v for k, v in overrides.items()}
    return dataclasses.replace(base, **overrides)


class Detector:
    """A config plus its network, with pure functions of (variables, inputs)."""

    def __init__(self, cfg):
        self.config = cfg
        self.module = cfg.build()

    @property
    def name(self) -> str:
        return self.config.name

    def dummy_inputs(self, batch_size: int = 1, seed: int = 0, occupancy: float = 0.5) -> dict:
        """A valid input pytree for this detector."""
        return self.config.dummy_inputs(batch_size, seed, occupancy)

    def init(self, rng: jax.Array) -> dict:
        """Fresh variables: {'params': ..., 'batch_stats': ...}."""
        return jax.jit(lambda r, x: self.module.init(r, **x, train=False))(rng, self.dummy_inputs(1))

    def apply(self, variables: dict, inputs: dict, train: bool = False):
        """Head outputs. With train=True, batch statistics are used and updated, and the
        result is (outputs, {'batch_stats': new_stats})."""
        if train:
            return self.module.apply(variables, **inputs, train=True, mutable=["batch_stats"])
        return self.module.apply(variables, **inputs, train=False)

    def apply_method(self, variables: dict, method: str, *args, train: bool = False):
        """Run one stage (`encode`, `backbone`, `detect`) in eval mode: for profiling and probes."""
        return self.module.apply(variables, *args, train=train, method=method)


def deploy_config(cfg):
    """The inference-form config of any variant (itself for families without one)."""
    return family_of(cfg).deploy_config(cfg)


def deploy(detector: Detector, variables: dict) -> tuple[Detector, dict]:
    """The inference form of a re-parameterizable detector (RadarNeXt: MobileOne branches fused
    into single convs, training-only outputs dropped) and its variables; eval-mode outputs agree.
    Families without a deploy form come back unchanged."""
    family = family_of(detector.config)
    fused = family.deploy_config(detector.config)
    if fused == detector.config:
        return detector, variables
    return Detector(fused), family.deploy_variables(detector.config, variables)


def input_columns(name: str) -> str:
    """The point columns variant `name` reads from a source (data.points.sources.load_frames'
    features): a source's own ('native': VoD's 7, TJ4D's 8) or the nuScenes ones ('dsfec')."""
    return family_of(name).points.input_columns


def create(name: str, /, **overrides) -> Detector:
    """A detector of the registered variant `name`, any config field overridden."""
    return Detector(config(name, **overrides))


WEIGHTS_DIR = Path(__file__).parent / "weights"


def shipped_weights(name: str) -> Path:
    return WEIGHTS_DIR / f"{name}.msgpack"


def load_variables(detector: Detector, path: str | Path) -> dict:
    """{'params', 'batch_stats'} from a weights file or a training checkpoint, shape-checked."""
    from .core import checkpoint

    raw = checkpoint.load(path)
    missing = [k for k in ("params", "batch_stats") if k not in raw]
    if missing:
        raise ValueError(f"{path}: expected a variables tree with {missing}; found keys {sorted(raw)}")
    target = jax.eval_shape(detector.init, jax.random.key(0))
    return checkpoint.load(path, {"params": target["params"], "batch_stats": target["batch_stats"],
                                  **{k: v for k, v in raw.items() if k not in ("params", "batch_stats")}})


def model_variables(detector: Detector, path: str | Path) -> dict:
    """{'params', 'batch_stats'} of a weights file or checkpoint (load_variables without the
    optimizer state and step a training checkpoint also holds): what a predictor or export runs."""
    variables = load_variables(detector, path)
    return {"params": variables["params"], "batch_stats": variables["batch_stats"]}


def overrides_of(cfg) -> dict:
    """The fields of `cfg` that differ from its registered variant's (`cfg.name`): what
    `config(cfg.name, **overrides_of(cfg))` needs to give `cfg` back."""
    base = config(cfg.name)
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg) if getattr(cfg, f.name) != getattr(base, f.name)}


def trained_detector(cfg, weights: str | Path | None = None) -> tuple[Detector, dict]:
    """The detector of `cfg` and its variables from `weights` (a weights file or checkpoint; default
    the shipped weights of `cfg.name`); FileNotFoundError saying how to get weights when none are there."""
    path = Path(weights) if weights else shipped_weights(cfg.name)
    detector = Detector(cfg)
    if not path.is_file():
        raise FileNotFoundError(f"no weights at {path}" + ("" if weights else f": {cfg.name!r} ships no weights yet; "
                                f"train with `dsfec train --model {cfg.name}` and pass --weights"))
    return detector, model_variables(detector, path)


def trained_fields(path: str | Path, fields) -> dict:
    """The values of config `fields` in the training record of a weights file: its manifest's
    "training" (shipped weights, `dsfec ship`), else the run.json of the run directory a checkpoint
    sits in (RUN/checkpoints/*.msgpack); {} when neither records them."""
    from .core.checkpoint import manifest_path

    path = Path(path)
    if not fields:
        return {}
    for record, key in ((manifest_path(path), "training"), (path.parent.parent / "run.json", None)):
        try:
            info = json.loads(record.read_text())
        except (OSError, ValueError):
            continue
        info = (info.get(key) or {}) if key else info
        found = {k: v for k, v in (info.get("overrides") or {}).items() if k in fields}
        if found:
            return {k: tuple(v) if isinstance(v, list) else v for k, v in found.items()}
    return {}
