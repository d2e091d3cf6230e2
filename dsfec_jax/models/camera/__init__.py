"""The camera family: YOLOv3 detectors on RGB images (Shuffle-YOLOv3 and the Darknet53 baseline)."""
