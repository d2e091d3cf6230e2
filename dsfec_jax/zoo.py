"""The model zoo: the registry of named variants, their configs, detectors and weights files.

    >>> from dsfec_jax import zoo
    >>> zoo.available("dsfec")
    ['baseline', 'dsfec_l', 'dsfec_m', 'dsfec_s']
    >>> det = zoo.create("dsfec_s", stem_filters=16)
    >>> variables = det.init(jax.random.key(0))
    >>> heads = det.apply(variables, det.dummy_inputs(1))
    >>> zoo.available_auxiliary()                    # registered networks that are not detectors
    ['monodepth_street', 'monodepth_tiny']
    >>> depth = zoo.create_auxiliary("monodepth_street")
    >>> variables = zoo.model_variables(depth, zoo.shipped_weights("monodepth_street"))

It sits above `models/` and imports nothing above them (models, core): a ready predictor of
trained weights is `dsfec_jax.api.load`, which asks the model's modality for it.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import jax

from .layers import bn_fold, conv_product
from .models.auxiliary import Auxiliary
from .models.camera.family import FAMILY as CAMERA
from .models.depth.auxiliary import AUXILIARY as DEPTH
from .models.dsfec.family import FAMILY as DSFEC
from .models.family import MODALITIES, Family
from .models.radarnext.family import FAMILY as RADARNEXT
from .models.yolo_rd.family import FAMILY as YOLO_RD

# The registry of families: a new family is its folder under models/ plus one entry here.
FAMILIES: dict[str, Family] = {f.name: f for f in (DSFEC, RADARNEXT, YOLO_RD, CAMERA)}
REGISTRY: dict[str, Any] = {name: cfg for f in FAMILIES.values() for name, cfg in f.variants.items()}
# Networks that are not detectors (models/auxiliary.py): named, built and loaded as the detectors are
AUXILIARIES: dict[str, Auxiliary] = {a.name: a for a in (DEPTH,)}
AUXILIARY_REGISTRY: dict[str, Any] = {name: cfg for a in AUXILIARIES.values() for name, cfg in a.variants.items()}


def available(family: str | None = None, modality: str | None = None) -> list[str]:
    """Names of the registered variants, optionally of one family (a key of FAMILIES) or of one
    modality ('points': the point-cloud families; 'rd': range-Doppler maps; 'image': camera images)."""
    if family is not None and family not in FAMILIES:
        raise KeyError(f"unknown family {family!r}; families: {sorted(FAMILIES)}")
    if modality is not None and modality not in MODALITIES:
        raise KeyError(f"unknown modality {modality!r}; modalities: {MODALITIES}")
    names = REGISTRY if family is None else FAMILIES[family].variants
    return sorted(n for n in names if modality is None or family_of(n).reads(modality))


def family_of(cfg_or_name) -> Family:
    """The Family record of a config (or of a registered variant's name)."""
    cfg = config(cfg_or_name) if isinstance(cfg_or_name, str) else cfg_or_name
    for family in FAMILIES.values():
        if type(cfg) is family.config_class:
            return family
    raise TypeError(f"{type(cfg).__name__} belongs to no registered family; families: {sorted(FAMILIES)}")


def config(name: str, /, **overrides):
    """The frozen config of `name` (a detector's or an auxiliary model's) with `overrides` applied (validated)."""
    base = REGISTRY.get(name) or AUXILIARY_REGISTRY.get(name)
    if base is None:
        raise KeyError(f"unknown model {name!r}; available: {available()}; auxiliary: {available_auxiliary()}")
    fields = {f.name for f in dataclasses.fields(base)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise TypeError(f"unknown field(s) {unknown} for {name!r}; valid fields: {sorted(fields)}")
    overrides = {k: tuple(v) if isinstance(v, list) else v for k, v in overrides.items()}
    return dataclasses.replace(base, **overrides)


class Detector:
    """A config plus its network, with pure functions of (variables, inputs)."""

    collections = ("params", "batch_stats")  # what its weights files hold

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

    def variable_shapes(self) -> dict:
        """init's tree as shapes and dtypes, computed without running it."""
        return jax.eval_shape(self.init, jax.random.key(0))

    def apply(self, variables: dict, inputs: dict, train: bool = False):
        """Head outputs. With train=True, batch statistics are used and updated, and the
        result is (outputs, {'batch_stats': new_stats})."""
        if train:
            return self.module.apply(variables, **inputs, train=True, mutable=["batch_stats"])
        return self.module.apply(variables, **inputs, train=False)

    def replaced(self, **fields) -> "Detector":
        """The same kind of detector on this config with `fields` replaced (an implementation
        choice such as `kernels`: the variables stay valid)."""
        return Detector(dataclasses.replace(self.config, **fields))

    def apply_method(self, variables: dict, method: str, *args, train: bool = False):
        """Run one stage (`encode`, `backbone`, `detect`) in eval mode: for profiling and probes."""
        return self.module.apply(variables, *args, train=train, method=method)


def deploy_config(cfg):
    """The inference-form config of any variant (itself for families without one)."""
    return family_of(cfg).deploy_config(cfg)


class FoldedDetector(Detector):
    """A detector whose evaluation-mode BatchNorms are folded into the convs before them
    (layers/bn_fold.py): the same `config`, `apply` and `apply_method` on folded variables,
    evaluation only. With `conv_products` (the JAX runtime's form), the small wide convs run as one
    matrix product on the CPU (layers/conv_product.py); an export keeps plain convs."""

    def __init__(self, cfg, plan: bn_fold.FoldPlan, conv_products: bool = True):
        super().__init__(cfg)
        self.plan = plan
        self.conv_products = conv_products
        call = conv_product.product_call(self.module.apply) if conv_products else self.module.apply
        self._eval = bn_fold.folded_call(call, plan)  # the fold's interceptor outside: it adds after each conv

    def replaced(self, **fields) -> "FoldedDetector":
        return FoldedDetector(dataclasses.replace(self.config, **fields), self.plan, self.conv_products)

    def init(self, rng: jax.Array) -> dict:
        """Fresh variables, folded."""
        return bn_fold.folded_variables(super().init(rng), self.plan)

    def apply(self, variables: dict, inputs: dict, train: bool = False):
        if train:
            raise ValueError(f"{self.name}: a BatchNorm-folded detector runs in evaluation only; "
                             "train the detector zoo.create builds")
        return self._eval(variables, **inputs, train=False)

    def apply_method(self, variables: dict, method: str, *args, train: bool = False):
        if train:
            raise ValueError(f"{self.name}: a BatchNorm-folded detector runs in evaluation only")
        return self._eval(variables, *args, train=False, method=method)


class InferenceForm:
    """How one detector runs at inference, found from its config alone (no weights needed): the
    family's deploy form (RadarNeXt: MobileOne branches fused, training-only outputs dropped), then
    every conv -> BatchNorm pair folded (layers/bn_fold.py, as ultralytics' `fuse()`).
    `.detector` runs what `.variables(trained)` gives; eval-mode outputs agree to float rounding."""

    def __init__(self, detector: Detector, for_export: bool = False):
        self.trained_config = detector.config
        self.family = family_of(detector.config)
        deployed = Detector(self.family.deploy_config(detector.config))
        inputs = jax.eval_shape(lambda: deployed.dummy_inputs(1))
        plan = bn_fold.find_folds(lambda v, x: deployed.module.apply(v, **x, train=False),
                                  deployed.variable_shapes(), inputs)
        self.detector = FoldedDetector(deployed.config, plan, conv_products=not for_export)

    def variables(self, trained: dict) -> dict:
        """Trained variables (`params`, `batch_stats`) -> the inference form's."""
        if self.detector.config != self.trained_config:
            trained = self.family.deploy_variables(self.trained_config, trained)
        return bn_fold.folded_variables(trained, self.detector.plan)


def deploy(detector: Detector, variables: dict, fold_batch_norm: bool = True,
           for_export: bool = False) -> tuple[Detector, dict]:
    """The inference form of any detector and its variables (InferenceForm); eval-mode outputs
    agree. `fold_batch_norm=False`: the family's deploy form only, BNs kept (what the papers count
    parameters of; unchanged for families without one). `for_export`: every conv stays a conv (no
    CPU matrix-product form), as an ONNX graph wants. A folded detector comes back as it is."""
    if isinstance(detector, FoldedDetector):
        if for_export and detector.conv_products:
            return FoldedDetector(detector.config, detector.plan, conv_products=False), variables
        return detector, variables
    if fold_batch_norm:
        form = InferenceForm(detector, for_export)
        return form.detector, form.variables(variables)
    family = family_of(detector.config)
    fused = family.deploy_config(detector.config)
    if fused == detector.config:
        return detector, variables
    return Detector(fused), family.deploy_variables(detector.config, variables)


def create(name: str, /, **overrides) -> Detector:
    """A detector of the registered variant `name`, any config field overridden."""
    if name in AUXILIARY_REGISTRY:
        raise KeyError(f"{name!r} is an auxiliary model ({auxiliary_of(name).task}), not a detector: "
                       "zoo.create_auxiliary builds it")
    return Detector(config(name, **overrides))


def available_auxiliary(kind: str | None = None) -> list[str]:
    """Names of the registered auxiliary models' variants, optionally of one record (a key of AUXILIARIES)."""
    if kind is not None and kind not in AUXILIARIES:
        raise KeyError(f"unknown auxiliary model {kind!r}; auxiliary models: {sorted(AUXILIARIES)}")
    return sorted(AUXILIARY_REGISTRY if kind is None else AUXILIARIES[kind].variants)


def auxiliary_of(cfg_or_name) -> Auxiliary:
    """The Auxiliary record of a config (or of a registered auxiliary variant's name)."""
    cfg = config(cfg_or_name) if isinstance(cfg_or_name, str) else cfg_or_name
    for record in AUXILIARIES.values():
        if type(cfg) is record.config_class:
            return record
    raise TypeError(f"{type(cfg).__name__} belongs to no registered auxiliary model; "
                    f"auxiliary models: {sorted(AUXILIARIES)}")


class AuxiliaryNet:
    """An auxiliary model's config plus its network: what the zoo's loader needs of a Detector."""

    def __init__(self, cfg):
        self.config = cfg
        self.record = auxiliary_of(cfg)
        self.module = self.record.build(cfg)
        self.collections = self.record.collections

    @property
    def name(self) -> str:
        return self.config.name

    def dummy_inputs(self, batch_size: int = 1) -> tuple:
        return self.record.dummy_inputs(self.config, batch_size)

    def init(self, rng: jax.Array) -> dict:
        """Fresh variables (the record's initialiser)."""
        return self.record.init(self.config, rng)

    def variable_shapes(self) -> dict:
        return jax.eval_shape(self.module.init, jax.random.key(0), *self.dummy_inputs(1))

    def apply(self, variables: dict, *inputs):
        return self.module.apply(variables, *inputs)


def create_auxiliary(name: str, /, **overrides) -> AuxiliaryNet:
    """The auxiliary model of the registered variant `name`, any config field overridden."""
    if name not in AUXILIARY_REGISTRY:
        raise KeyError(f"unknown auxiliary model {name!r}; auxiliary: {available_auxiliary()}")
    return AuxiliaryNet(config(name, **overrides))


WEIGHTS_DIR = Path(__file__).parent / "weights"


def shipped_weights(name: str) -> Path:
    """The weights shipped for variant `name`: WEIGHTS_DIR/NAME.msgpack for a detector, in its
    record's folder for an auxiliary model (weights/depth/monodepth_street.msgpack)."""
    if name in AUXILIARY_REGISTRY:
        return WEIGHTS_DIR / auxiliary_of(name).name / f"{name}.msgpack"
    return WEIGHTS_DIR / f"{name}.msgpack"


def load_variables(model: Detector | AuxiliaryNet, path: str | Path) -> dict:
    """The model's collections ({'params', 'batch_stats'} for a detector, {'params'} for the depth
    network) from a weights file or a training checkpoint, shape-checked and on the device (jax
    arrays); a checkpoint's other entries (optimizer state, step) come back as stored. A checkpoint
    of a run with a weight EMA gives the average's collections (core/averaged_weights.py)."""
    from .core import checkpoint, run_checkpoints
    from .core.averaged_weights import EMA_KEY, weights_of

    orbax = not Path(path).is_file()  # a training checkpoint's step directory (or checkpoints/best)
    raw = run_checkpoints.read_state(path) if orbax else checkpoint.load(path)
    missing = [k for k in model.collections if k not in weights_of(raw)]
    if missing:
        raise ValueError(f"{path}: expected a variables tree with {missing}; found keys {sorted(weights_of(raw))}")
    target = model.variable_shapes()

    def shaped(tree: dict, where: str = "") -> dict:  # the model's collections shape-checked, the rest as stored
        kept = [k for k in model.collections if k in tree]
        return {**tree, **checkpoint.restored(path, {k: tree[k] for k in kept}, {k: target[k] for k in kept}, where)}

    loaded = shaped(raw)
    if EMA_KEY in raw:
        loaded[EMA_KEY] = shaped(raw[EMA_KEY], f"[{EMA_KEY!r}]")
    weights = weights_of(loaded)  # a run's weight average, where it kept one (what it validated)
    # on the device once: a jitted call converts every numpy argument again on every call (the cost:
    # docs/range-doppler.md, Deploy)
    return {**loaded, **jax.device_put({k: weights[k] for k in model.collections})}


def model_variables(model: Detector | AuxiliaryNet, path: str | Path) -> dict:
    """The model's collections of a weights file or checkpoint (load_variables without the
    optimizer state and step a training checkpoint also holds): what a predictor or export runs."""
    variables = load_variables(model, path)
    return {k: variables[k] for k in model.collections}


def training_record(path: str | Path) -> dict:
    """How a weights file or checkpoint was trained: its manifest's "training" (`dsfec ship`, `dsfec
    depth ship`, a finished depth run's weights), else what an auxiliary model's record reads from a
    manifest of its first format, else the run.json of the run directory a checkpoint sits in
    (RUN/checkpoints/...); {} when none is readable."""
    from .core.checkpoint import manifest_path
    from .core.run_checkpoints import run_dir_of

    path = Path(path)
    for record in (manifest_path(path), run_dir_of(path) / "run.json"):
        try:
            info = json.loads(record.read_text())
        except (OSError, ValueError):
            continue
        if not isinstance(info, dict):
            continue
        if record.name == "run.json":
            return info
        if isinstance(info.get("training"), dict):
            return info["training"]
        for aux in AUXILIARIES.values():
            first = aux.first_format_training(info) if aux.first_format_training else None
            if first is not None:
                return first
    return {}


def auxiliary_config(path: str | Path, kind: str):
    """The config of auxiliary model `kind` that the weights or checkpoint at PATH were trained
    with: the whole config of its training record (a run may change any field; the depth network's
    `--input` changes its input size but no weight's shape, so the name alone would run it wrong)."""
    if kind not in AUXILIARIES:
        raise KeyError(f"unknown auxiliary model {kind!r}; auxiliary models: {sorted(AUXILIARIES)}")
    from .core.run_checkpoints import readable

    if not readable(path):
        raise FileNotFoundError(f"{path}: no such checkpoint/weights file")
    recorded = training_record(path).get("config")
    if not isinstance(recorded, dict):
        from .core.checkpoint import manifest_path

        raise ValueError(f"{manifest_path(path)}: no 'config' in its training record, and no run.json of a "
                         f"training run beside it; expected weights of a {kind} training run, shipped weights "
                         "or a training checkpoint")
    try:
        return AUXILIARIES[kind].config_from_dict(recorded)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: its training record's config: {err}") from err


def overrides_of(cfg) -> dict:
    """The fields of `cfg` that differ from its registered variant's (`cfg.name`): what
    `config(cfg.name, **overrides_of(cfg))` needs to give `cfg` back."""
    base = config(cfg.name)
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg) if getattr(cfg, f.name) != getattr(base, f.name)}


def trained_detector(cfg, weights: str | Path | None = None) -> tuple[Detector, dict]:
    """The detector of `cfg` and its variables from `weights` (a weights file or checkpoint; default
    the shipped weights of `cfg.name`); FileNotFoundError saying how to get weights when none are there."""
    from .core.run_checkpoints import readable

    path = Path(weights) if weights else shipped_weights(cfg.name)
    detector = Detector(cfg)
    if not readable(path):
        raise FileNotFoundError(f"no weights at {path}" + ("" if weights else f": {cfg.name!r} ships no weights yet; "
                                f"train with `dsfec train --model {cfg.name}` and pass --weights"))
    return detector, model_variables(detector, path)


def trained_fields(path: str | Path, fields) -> dict:
    """The values of config `fields` in the training record of a weights file: its manifest's
    "training" (shipped weights, `dsfec ship`), else the run.json of the run directory a checkpoint
    sits in (RUN/checkpoints/...); {} when neither records them."""
    from .core.checkpoint import manifest_path
    from .core.run_checkpoints import run_dir_of

    path = Path(path)
    if not fields:
        return {}
    for record, key in ((manifest_path(path), "training"), (run_dir_of(path) / "run.json", None)):
        try:
            info = json.loads(record.read_text())
        except (OSError, ValueError):
            continue
        info = (info.get(key) or {}) if key else info
        found = {k: v for k, v in (info.get("overrides") or {}).items() if k in fields}
        if found:
            return {k: tuple(v) if isinstance(v, list) else v for k, v in found.items()}
    return {}
