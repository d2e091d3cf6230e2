"""Angular occlusion: a scatterer is shadowed when a nearer actor spans its azimuth in that sweep.

Each actor's shadow is the azimuth interval of its BEV corners seen from the sensor position of
the sweep, starting at its nearest corner. Radar leaks under and around vehicles, so a shadowed
scatterer is lost with probability `occlusion_prob`, not always.
"""

from __future__ import annotations

import numpy as np

from ....boxes.geometry import bev_corners
from .scene import Actors
from .sensor import Echoes, Sweeps, polar, wrap


def shadows(actors: Actors, sweeps: Sweeps):
    """Per sweep and actor (S, M): shadow start azimuth in (-pi, pi], end (may pass pi), nearest range."""
    m = len(actors)
    corners = bev_corners(np.zeros((m, 2)), actors.size[:, :2], actors.yaw)       # (M, 4, 2)
    c = actors.center_at(sweeps.t)                                                # (S, M, 2)
    _, az_c = polar(c, sweeps.pos[:, None, :])
    r_k, az_k = polar(c[:, :, None, :] + corners[None], sweeps.pos[:, None, None, :])
    off = wrap(az_k - az_c[..., None])
    lo = wrap(az_c + off.min(-1))
    return lo, lo + (off.max(-1) - off.min(-1)), r_k.min(-1)


def shadowed(actors: Actors, sweeps: Sweeps, e: Echoes, max_range: float, margin: float = 0.3) -> np.ndarray:
    """(P,) bool: echo p lies behind some other actor in its sweep."""
    if len(actors) == 0 or len(e) == 0:
        return np.zeros(len(e), bool)
    lo, hi, near = shadows(actors, sweeps)
    blockers = np.flatnonzero((near < max_range).any(0))  # far actors shadow nothing we keep
    lo, hi, near = lo[:, blockers], hi[:, blockers], near[:, blockers]
    r, az = polar(e.xy, sweeps.pos[e.sweep])
    out = np.zeros(len(e), bool)
    maybe = np.flatnonzero(r > near.min(initial=np.inf) + margin)  # nearer than every blocker: free
    k, r, az = e.sweep[maybe], r[maybe, None], az[maybe, None]
    lo, hi, near = lo[k], hi[k], near[k]                                          # (P, M)
    # az is in (-pi, pi]; a shadow that runs past pi is met again at az + 2 pi.
    inside = ((az >= lo) & (az <= hi)) | (az + 2 * np.pi <= hi)
    behind = (near < r - margin) & (e.owner[maybe, None] != blockers)
    out[maybe] = np.any(inside & behind, axis=1)
    return out
