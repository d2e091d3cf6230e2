"""What a detector family is, as one record: shared code (training, prediction, export, search,
reports) asks the family of a config for what differs, and never compares family names.

A family lives in its own folder (`models/<family>/`: net, heads, variants, targets, loss, paper
numbers and `family.py` with its `FAMILY` record); `zoo.FAMILIES` lists the records. Adding a
family is that folder plus one line in `zoo.FAMILIES`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping

# A report column: (record key, column title, digits). The first column is the headline.
Column = tuple[str, str, int]


@dataclasses.dataclass(frozen=True)
class MetricProtocol:
    """How a family's detections are scored, and how its results are reported.

    `name` picks the metric among the modalities' `protocols` (modalities/registry.protocol; metrics never import models, so the
    record names the metric rather than holding it). `headline` is the key that ranks candidates
    and keeps the best checkpoint; `columns` lay out its ablation tables; `keep` is what a weights
    manifest records of a validation; `match_class`, if set, is the class whose per-frame matches a
    sweep keeps for bootstrap intervals ("*": every class of the model), `interval_statistic` names
    what those intervals resample (the mean over the kept classes of their AP averaged over
    `interval_thresholds`, None: every threshold the tables hold), and `zero_class_note` names
    classes scoring 0 everywhere."""

    name: str
    headline: str
    columns: tuple[Column, ...]
    keep: tuple[str, ...]
    match_class: str | None = None
    interval_statistic: str = "Car mAP"
    interval_thresholds: tuple[float, ...] | None = None
    zero_class_note: bool = False


@dataclasses.dataclass(frozen=True)
class Supernet:
    """Weight sharing over one depth axis (search.oneshot): the subnet of `depth` (ints, one per
    stage; may be traced) runs the first depth[s] blocks of stage s. `field` is the config field
    the candidates differ in; `blocks(cfg)` maps each top-level module of the supernet that a
    subnet may leave idle to its (stage, block) indices; the network takes `depth` as an input
    named `input`. `bn_momentum` is the family's batch-norm momentum (for recalibration)."""

    field: str
    blocks: Callable[[Any], Mapping[str, tuple[int, int]]]
    bn_momentum: float
    input: str = "depth"


@dataclasses.dataclass(frozen=True)
class SearchRecipe:
    """How much a search trial of this family trains and where it is measured (search.recipes
    turns it into a Recipe). `schedule` names a train.schedules preset; `schedule_changes`
    override its fields; `grid` None keeps the model's own grid; `window` None trains on the
    whole (recipe) grid; `supernet_steps` None means the schedule's length; `oneshot_seeds` is
    how many supernets (seeds) a one-shot search trains when `--seeds` is not given.
    `max_pillars`, `grid` and `window` are the point families' (None for a range-Doppler family:
    frames are then RD samples)."""

    schedule: str
    schedule_changes: Mapping[str, Any]
    train_frames: int
    val_frames: int
    grid: Any
    max_pillars: int | None
    window: int | None
    latency_repeats: int
    supernet_steps: int | None
    light_profile: bool
    warm_start: bool = False
    oneshot_seeds: int = 1


# point clouds (pillarized); range-Doppler maps (image-like, 2D boxes in map cells); RGB camera
# images (2D boxes in image pixels); each one's pipeline is dsfec_jax/modalities/<name>/
MODALITIES = ("points", "rd", "image")


@dataclasses.dataclass(frozen=True)
class PointParts:
    """What only a point-cloud family has (pillars, BEV boxes, rotated NMS).

    `input_columns` ("dsfec": every source mapped onto nuScenes' columns; "native": a source's
    own); `targets(cfg)` -> fn(boxes, grid) -> one frame's target maps; `origin_input` (the
    network takes each training window's origin as an input, so one compiled step serves every
    window); `decoder(cfg, top_k)` -> fn(head outputs) -> (boxes, scores, labels) before NMS
    (boxes: 5 BEV or 7 3D columns); `predictor` (defaults of the host pipeline: top_k, nms_iou,
    max_boxes); `map_outputs(cfg)` (names of the head maps an export adds) and
    `head_maps(cfg, outputs)` (those maps, in that order)."""

    input_columns: str
    targets: Callable[[Any], Callable]
    decoder: Callable[[Any, int], Callable]
    predictor: Mapping[str, Any]
    map_outputs: Callable[[Any], tuple[str, ...]]
    head_maps: Callable[[Any, Any], tuple]
    origin_input: bool = False


@dataclasses.dataclass(frozen=True)
class Family:
    """Everything that differs between detector families.

    Config and variants: `config_class`, `variants` (name -> frozen config). `modality`: what
    the family's networks read, 'points' (point clouds, pillarized; DSFEC, RadarNeXt), 'rd'
    (range-Doppler maps as images; the YOLO-RD family) or 'image' (RGB camera images; the camera
    YOLOv3 family). Shared code that only handles one
    modality asks for it (modalities/checks.require_modality) and fails with a clear message otherwise.
    Data: `benchmark` (the embedded synthetic source its commands default to).
    Training: `loss(cfg)` -> fn(outputs, targets) -> (loss, parts); `schedules` maps the
    commands' profiles (`--schedule quick|paper`) to train.schedules presets; `weight_ema`: whether
    `dsfec train` keeps, validates and ships a moving average of the weights unless told
    (--ema/--no-ema; train/ema.py).
    Inference: `head_classes(cfg)` -> {head: classes}.
    Point families: `points` (PointParts: columns, targets, decoder, predictor defaults, export
    maps); the others have none.
    Deploy: `deploy_config` / `deploy_variables` (the inference form; identity when there is none);
    `weight_fields`: config fields a training run sets from its data (the camera family's classes),
    which `api.load` reads back from the weights' training record.
    Measurement: `metric` (MetricProtocol), `stem_memory(cfg, variables)` (a paper's memory
    figure in MiB, or None) and `memory_convention` (what that figure counts). Search: `recipes` (name -> SearchRecipe), `axes` (derived search axes:
    name -> fn(base_cfg, overrides, value) -> overrides), `supernet` (or None)."""

    name: str
    config_class: type
    variants: Mapping[str, Any]
    benchmark: str
    loss: Callable[[Any], Callable]
    head_classes: Callable[[Any], dict]
    metric: MetricProtocol
    modality: str = "points"
    schedules: Mapping[str, str] = dataclasses.field(default_factory=lambda: {"quick": "quick", "paper": "paper"})
    points: PointParts | None = None
    weight_ema: bool = False
    recipes: Mapping[str, SearchRecipe] = dataclasses.field(default_factory=dict)
    axes: Mapping[str, Callable] = dataclasses.field(default_factory=dict)
    supernet: Supernet | None = None
    deploy_config: Callable[[Any], Any] = lambda cfg: cfg
    deploy_variables: Callable[[Any, dict], dict] = lambda cfg, variables: variables
    stem_memory: Callable[[Any, dict], float] | None = None
    weight_fields: tuple[str, ...] = ()
    memory_convention: str = "stem input + output maps (float32, batch 1) + stem weights, MiB (DSFEC Table 2)"

    def reads(self, modality: str) -> bool:
        """Whether the family's networks read `modality` (a name of MODALITIES): the one place a
        listing by modality compares names."""
        return self.modality == modality

    def __post_init__(self):
        wrong = [n for n, cfg in self.variants.items() if not isinstance(cfg, self.config_class)]
        if wrong:
            raise TypeError(f"family {self.name!r}: variants {wrong} are not {self.config_class.__name__}")
        if self.modality not in MODALITIES:
            raise ValueError(f"family {self.name!r}: modality {self.modality!r}; expected one of {MODALITIES}")
        if (self.modality == "points") != (self.points is not None):
            raise ValueError(f"family {self.name!r}: PointParts are for point-cloud families, and they need them")
