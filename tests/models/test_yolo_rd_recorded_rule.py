"""The YOLO-RD family trains with ultralytics 8.4.190's small-box rule by default (issue 49). The
shipped RD weights, retrained with it on benchmark v2 (issue 54), rebuild their config from the
command their manifest records; the tables and NAS records made under the earlier (8, 16) rule
keep it pinned."""

import dataclasses
import json
import shlex

import pytest

from dsfec_jax import cli, zoo
from dsfec_jax.core.provenance import jsonable
from dsfec_jax.models.yolo_rd.config import REFERENCE_SMALL_SIDE, EARLIER_SMALL_SIDE, YoloRDConfig

RD_WEIGHTS = sorted(p for p in zoo.WEIGHTS_DIR.glob("*.msgpack") if zoo.family_of(p.stem).modality == "rd")


def test_new_training_defaults_to_the_reference_rule():
    assert YoloRDConfig().assign_small_side == REFERENCE_SMALL_SIDE == (16.0, 16.0)
    assert all(zoo.config(p.stem).assign_small_side == REFERENCE_SMALL_SIDE for p in RD_WEIGHTS)


@pytest.mark.parametrize("path", RD_WEIGHTS, ids=lambda p: p.stem)
def test_a_shipped_manifests_command_rebuilds_the_config_it_was_trained_with(path):
    """`dsfec train` run with the manifest's command (its reproduce command, where the weights ran
    under an earlier default) gets the recorded config, small-box rule included."""
    training = json.loads(path.with_name(path.name + ".json").read_text())["training"]
    args = cli.parse(shlex.split(training.get("reproduce_command", training["command"]))[1:])
    config = zoo.config(args.model, **cli.parse_overrides(args.set))
    assert tuple(training["config"]["assign_small_side"]) == REFERENCE_SMALL_SIDE  # retrained under today's rule
    rebuilt = jsonable(dataclasses.asdict(config))
    assert {k: rebuilt[k] for k in training["config"]} == training["config"]  # fields added since: defaults


def test_the_nas_space_and_its_registered_subnet_keep_the_rule_the_readmes_nas_figures_used():
    from search.nas.spaces import get_space

    space = get_space("yolov8n_adapter")
    for genes in (space.smallest(), space.largest()):  # supernet, stand-alone retraining and registration
        assert zoo.config(space.base, **space.overrides(genes)).assign_small_side == EARLIER_SMALL_SIDE
    assert zoo.config("yolov8n_adapter_search").assign_small_side == EARLIER_SMALL_SIDE
