"""RadarNeXt's published numbers (Tables I-III, arXiv 2501.02314), for side-by-side reports.

mAP on the VoD validation set (entire annotated area, 5 scans) unless a key says TJ4D; FPS on an
RTX A4000 and a Jetson AGX Orin. Table III keys are DCNv3 positions (Figure 2 numbering).
"""

TABLE1 = {  # VoD Car/Ped/Cyc/mAP; TJ4D Car/Ped/Cyc/Truck/mAP; FPS
    "radarnext_fpn": {"params": 0.899e6, "vod": {"Car": 37.96, "Pedestrian": 38.28, "Cyclist": 67.69, "mAP": 47.98},
                      "tj4d": {"Car": 18.64, "Pedestrian": 28.67, "Cyclist": 63.88, "Truck": 16.17, "mAP": 31.84},
                      "fps_a4000": 83.57, "fps_orin": 33.07},
    "radarnext_pan": {"params": 1.531e6, "vod": {"Car": 35.47, "Pedestrian": 36.1, "Cyclist": 72.89, "mAP": 48.15},
                      "tj4d": {"Car": 20.49, "Pedestrian": 26.10, "Cyclist": 54.90, "Truck": 18.02, "mAP": 29.88},
                      "fps_a4000": 70.97, "fps_orin": 31.43},
    "radarnext_mdfen": {"params": 1.580e6, "vod": {"Car": 37.44, "Pedestrian": 41.83, "Cyclist": 72.16, "mAP": 50.48},
                        "tj4d": {"Car": 26.24, "Pedestrian": 24.55, "Cyclist": 59.78, "Truck": 18.64, "mAP": 32.30},
                        "fps_a4000": 67.10, "fps_orin": 28.40},
}
TABLE2 = {  # Dense (PointPillars backbone) vs Rep-DWC: params, VoD mAP, FPS A4000, FPS Orin
    "radarnext_fpn_dense": {"params": 4.726e6, "mAP": 48.89, "fps_a4000": 72.33, "fps_orin": 30.83},
    "radarnext_fpn": {"params": 0.899e6, "mAP": 47.98, "fps_a4000": 83.57, "fps_orin": 33.07},
    "radarnext_pan_dense": {"params": 5.337e6, "mAP": 47.72, "fps_a4000": 69.07, "fps_orin": 29.63},
    "radarnext_pan": {"params": 1.531e6, "mAP": 48.15, "fps_a4000": 70.97, "fps_orin": 31.43},
    "radarnext_mdfen_dense": {"params": 5.385e6, "mAP": 48.23, "fps_a4000": 61.43, "fps_orin": 27.13},
    "radarnext_mdfen": {"params": 1.580e6, "mAP": 50.48, "fps_a4000": 67.10, "fps_orin": 28.40},
}
TABLE3 = {  # DCNv3 positions of RadarNeXt (MDFEN): params, VoD mAP, FPS A4000, FPS Orin
    (1,): {"params": 1.694e6, "mAP": 48.09, "fps_a4000": 69.30, "fps_orin": 29.73},
    (3,): {"params": 1.630e6, "mAP": 48.35, "fps_a4000": 68.33, "fps_orin": 30.13},
    (5,): {"params": 1.547e6, "mAP": 49.13, "fps_a4000": 68.90, "fps_orin": 30.60},
    (2,): {"params": 1.694e6, "mAP": 47.45, "fps_a4000": 68.30, "fps_orin": 28.80},
    (4,): {"params": 1.580e6, "mAP": 50.48, "fps_a4000": 67.10, "fps_orin": 28.40},
    (1, 2, 4): {"params": 1.905e6, "mAP": 46.96, "fps_a4000": 59.87, "fps_orin": 25.50},
}
