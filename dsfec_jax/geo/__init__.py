"""Geolocation: from a detection's depth and the ego's GPS to a point on the map
(shuffle_yolov3_edge.txt §3.3; reference-spec §2).

    from dsfec_jax.geo import EgoTrack, Placer, clean_fixes, read_gps
    fixes, report = clean_fixes(read_gps("gps.csv"))         # bad fixes skipped and counted
    track = EgoTrack(fixes)                                   # local ENU about the first fix
    ego = track.state(t)                                      # position + heading at a frame time
    placer = Placer(cam.fx, cam.cx, track.origin, "center")
    objects, placed = placer.place(boxes, classes, scores, depth_m, ego.enu, ego.heading_rad)

Modules: geodesy (WGS84 <-> ECEF <-> ENU through pymap3d), gps (reading and cleaning fixes, the
interpolated ego track and its heading), placement (reference points, reading a depth map,
depth from disparity, lateral offset, ENU placement, the exchange format's placed objects and
frame batches), geojson (Features for objects and ego tracks), export (a drive's GeoJSON, CSV
and PNG), map_png (the top-view map, offline). geo imports only core/ of the project.

How well the track and placement do on the synthetic street drives (position and heading errors
of the interpolated track, placement errors with the exact depth) is in docs/edge-and-map-service.md,
"Track and placement, measured"; `python -m experiments.edge_errors` re-measures placement on a drive.
"""

from .geodesy import (ecef_to_enu, ecef_to_enu_vector, ecef_to_geodetic, enu_to_ecef, enu_to_ecef_vector,
                      enu_to_geodetic, geodetic_to_ecef, geodetic_to_enu)
from .gps import EgoState, EgoTrack, FixReport, GpsFixes, clean_fixes, read_gps, write_gps_csv
from .placement import (REFERENCE_POINTS, Placer, depth_from_disparity, frame_batch, lateral_offset, place_enu,
                        reference_pixels, sample_at)

__all__ = ["REFERENCE_POINTS", "EgoState", "EgoTrack", "FixReport", "GpsFixes", "Placer", "clean_fixes",
           "depth_from_disparity", "ecef_to_enu", "ecef_to_enu_vector", "ecef_to_geodetic", "enu_to_ecef",
           "enu_to_ecef_vector", "enu_to_geodetic", "frame_batch", "geodetic_to_ecef", "geodetic_to_enu",
           "lateral_offset", "place_enu", "read_gps", "reference_pixels", "sample_at", "write_gps_csv"]
