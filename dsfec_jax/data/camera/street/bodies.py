"""How each road user is built from a few boxes ("parts"), and the palettes they are painted from.

A part is (centre, half size, material, colour) in the object's own frame: `along` its heading,
`left`, `up` from the ground. Parts of one object never leave its 3D box (width, length, height),
which is the object's ground truth. Materials are rendered by shade.py:
- car: two axle blocks (tyres, hubs on the sides), a body (paint, lights front and back), a
  narrower cabin (glass with pillars, painted roof);
- truck: axles, a cab (windscreen, side windows), a cargo box;
- bus: axles, one tall body with a window band and a windscreen;
- pedestrian: legs (trousers), torso (shirt), head (skin, hair);
- cyclist: a bicycle (a thin slab, see-through but for tyres and frame), legs, torso, head.
"""

from __future__ import annotations

import numpy as np

# materials (shade.py)
PAINT, CABIN, WHEEL, BUS, CARGO, TRUCK_CAB, CLOTH, HEAD, BIKE, BUILDING, TRUNK, FOLIAGE, POLE, SIGN = range(14)

CAR_PAINTS = np.array([[235, 235, 235], [25, 25, 28], [170, 172, 178], [110, 112, 118], [165, 25, 25],
                       [30, 60, 140], [20, 35, 75], [40, 90, 50], [200, 185, 150], [230, 190, 30],
                       [120, 20, 30], [80, 130, 190]], np.float32) / 255
CAR_PAINT_P = np.array([0.22, 0.18, 0.16, 0.12, 0.07, 0.06, 0.05, 0.03, 0.03, 0.01, 0.04, 0.03])
BUS_PAINTS = np.array([[230, 230, 225], [230, 190, 30], [190, 30, 30], [40, 90, 170], [60, 140, 70]], np.float32) / 255
TRUCK_PAINTS = np.array([[235, 235, 235], [190, 30, 30], [40, 70, 150], [230, 120, 20], [120, 120, 125],
                         [60, 110, 60]], np.float32) / 255
SHIRTS = np.array([[200, 40, 40], [40, 60, 150], [230, 230, 230], [30, 30, 30], [60, 130, 60], [240, 200, 40],
                   [120, 80, 160], [150, 150, 150], [230, 120, 40], [90, 60, 40], [240, 150, 170]], np.float32) / 255
TROUSERS = np.array([[40, 60, 110], [25, 25, 30], [90, 90, 95], [170, 150, 110], [60, 50, 40]], np.float32) / 255
SKINS = np.array([[240, 205, 180], [225, 180, 150], [195, 145, 110], [150, 100, 70], [100, 65, 45]], np.float32) / 255
HAIRS = np.array([[30, 20, 15], [90, 60, 30], [200, 170, 110], [140, 140, 140], [60, 35, 20]], np.float32) / 255
BIKES = np.array([[30, 30, 30], [180, 30, 30], [40, 80, 160], [200, 200, 200], [40, 120, 60]], np.float32) / 255
DARK = np.array([0.08, 0.08, 0.09], np.float32)


def _jitter(rng: np.random.Generator, color: np.ndarray, amount: float = 0.06) -> np.ndarray:
    return np.clip(color * (1 + amount * rng.standard_normal()) + 0.02 * rng.standard_normal(3), 0, 1)


def sample_colors(rng: np.random.Generator, name: str) -> tuple[tuple[float, float, float], ...]:
    """The colours an object's parts use (roles depend on the class; see `parts`)."""
    def pick(table, p=None):
        return _jitter(rng, table[rng.choice(len(table), p=p)])
    if name == "car":
        roles = [pick(CAR_PAINTS, CAR_PAINT_P)]
    elif name == "truck":
        roles = [pick(TRUCK_PAINTS), pick(TRUCK_PAINTS)]     # cab, cargo
    elif name == "bus":
        roles = [pick(BUS_PAINTS)]
    elif name == "pedestrian":
        roles = [pick(SHIRTS), pick(TROUSERS), pick(SKINS), pick(HAIRS)]
    else:  # cyclist
        roles = [pick(SHIRTS), pick(TROUSERS), pick(SKINS), pick(HAIRS), pick(BIKES)]
    return tuple(tuple(float(x) for x in c) for c in roles)


def _box(along, left, z0, z1, half_along, half_left, material, color):
    color = np.asarray(color, np.float32)
    color = np.concatenate([color, color]) if len(color) == 3 else color  # (primary, secondary) rgb
    return ((along, left, (z0 + z1) / 2), (half_along, half_left, (z1 - z0) / 2), material, color)


def parts(name: str, size, colors) -> list[tuple]:
    """[(centre (along, left, up), half (along, left, up), material, (6,) primary + secondary rgb)]."""
    w, l, h = size
    c = [np.asarray(x, np.float32) for x in colors]
    if name == "car":
        r, axle = min(0.32, 0.22 * h), 0.3 * l
        return [_box(axle, 0, 0, 2 * r, r, w / 2, WHEEL, DARK), _box(-axle, 0, 0, 2 * r, r, w / 2, WHEEL, DARK),
                _box(0, 0, 0.17 * h, 0.62 * h, l / 2, w / 2 - 0.03, PAINT, c[0]),
                _box(-0.06 * l, 0, 0.62 * h, h, 0.28 * l, 0.43 * w, CABIN, c[0])]
    if name == "truck":
        r, cab = 0.5, min(2.2, 0.3 * l)
        return [_box(l / 2 - 1.3, 0, 0, 2 * r, r, w / 2, WHEEL, DARK),
                _box(-l / 2 + 1.6, 0, 0, 2 * r, r, w / 2, WHEEL, DARK),
                _box(l / 2 - cab / 2, 0, 0.45, 0.9 * h, cab / 2, w / 2 - 0.05, TRUCK_CAB, c[0]),
                _box(-cab / 2 - 0.1, 0, 0.8, h, (l - cab - 0.2) / 2, w / 2, CARGO, c[1])]
    if name == "bus":
        r = 0.5
        return [_box(l / 2 - 2.7, 0, 0, 2 * r, r, w / 2, WHEEL, DARK), _box(-l / 2 + 3.5, 0, 0, 2 * r, r, w / 2, WHEEL, DARK),
                _box(0, 0, 0.3, h, l / 2, w / 2 - 0.02, BUS, c[0])]
    if name == "pedestrian":
        return [_box(0, 0, 0, 0.47 * h, 0.11, 0.28 * w, CLOTH, c[1]),
                _box(0, 0, 0.47 * h, 0.84 * h, l / 2, w / 2, CLOTH, c[0]),
                _box(0, 0, 0.86 * h, h, 0.1, 0.085, HEAD, np.concatenate([c[2], c[3]]))]
    if name == "cyclist":
        return [_box(0, 0, 0, 0.6 * h, l / 2, 0.05, BIKE, c[4]),
                _box(-0.1, 0, 0.27 * h, 0.56 * h, 0.15, 0.25 * w, CLOTH, c[1]),
                _box(-0.05, 0, 0.56 * h, 0.85 * h, 0.2, w / 2, CLOTH, c[0]),
                _box(0.0, 0, 0.87 * h, h, 0.1, 0.085, HEAD, np.concatenate([c[2], c[3]]))]
    raise ValueError(f"no body for class {name!r}")
