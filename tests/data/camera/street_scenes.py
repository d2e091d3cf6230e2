"""Hand-built street worlds for the street benchmark's tests (no random draws)."""

import dataclasses

from dsfec_jax.data.camera.street.config import StreetConfig
from dsfec_jax.data.camera.street.road import CrossSection, Road
from dsfec_jax.data.camera.street.world import Actor, EgoPlan, Look, World

TINY = StreetConfig(width=64)  # the paper's camera at 64 x 36
LANE = -1.75                   # the ego lane's centre (one 3.5 m lane per direction)
RED = ((0.7, 0.1, 0.1),)


def car(i: int, s: float, d: float, **kw) -> Actor:
    return Actor(i, "car", s, d, size=(1.8, 4.5, 1.5), colors=RED, **kw)


def straight_world(actors=(), ego_s: float = 50.0, ego_d: float = LANE, speed: float = 0.0) -> World:
    """A straight road heading north from the ENU origin, nothing but `actors` on it, no noise."""
    road = Road.straight(1000.0, section=CrossSection(lanes=1, lane_width=3.5))
    return World(road, tuple(actors), look=Look(noise_sd=0.0), ego=EgoPlan(ego_s, ego_d, speed))


def config(**kw) -> StreetConfig:
    return dataclasses.replace(StreetConfig(), **kw)
