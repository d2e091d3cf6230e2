"""Per-class height and centre-z priors for detectors that predict only a BEV box (PIXOR code).

nuScenes-style submissions need a 3D box; the centre-distance metric ignores z and height, so
these only make the boxes plausible. Values are typical nuScenes sizes; z is the box centre in a
sensor frame mounted ~0.5 m above the road.
"""

HEIGHT = {"car": 1.6, "truck": 3.0, "bus": 3.3, "pedestrian": 1.75, "bicycle": 1.3, "cyclist": 1.7, "motorcycle": 1.5}
SENSOR_HEIGHT = 0.5
DEFAULT_HEIGHT = 1.6


def height(name: str) -> float:
    return HEIGHT.get(name, DEFAULT_HEIGHT)


def centre_z(name: str) -> float:
    return height(name) / 2 - SENSOR_HEIGHT
