"""The Shuffle-YOLOv3 paper's published numbers (../shared/papers/shuffle_yolov3_edge.txt) and
darknet's counts for YOLOv3, as data for side-by-side reports.

Ours (footprint.py, tests/models/camera/test_camera_models.py), 20 classes, 416 x 416, batch 1:
- Darknet53-YOLOv3: 61,626,049 params (+ 52,608 BN moving statistics; at 80 classes 61,949,149 and
  a weights file of 248,007,048 bytes, exactly yolov3.weights), 32.714 G MACs = 65.43 GFLOPs
  (darknet's 2 x MACs; 65.86 at 80 classes, the "65.9" usually quoted), 246.5 MB fp32.
- Shuffle-YOLOv3 (our layout): 1,660,353 params (6.64 MB), 1.820 G MACs = 3.64 GFLOPs: the paper's
  25 GFLOPs and 45.5 MB cannot come from shuffle units at Table 1's widths (docs/camera.md,
  "Camera detectors").
"""

# Table 1 ("Total computation") and Sec. 2.2: GFLOPs at 416 x 416
GFLOPS = {"yolov3_darknet53": 60.0, "shuffle_yolov3": 25.0}
GFLOPS_NOTE = ("Table 1 prints 60 and 25 GFLOPS; the text says YOLOv3 'will cost 60+ GFLOPS ... for input "
               "image size of 416x416': darknet's convention (2 x MACs), in which yolov3-voc is 65.43")
# Table 2 (traffic dataset, 6 classes): model size MB, mAP, CPU FPS
TABLE2 = {
    "yolov3_darknet53": {"size_mb": 243.0, "mAP": 71.8, "fps_cpu": 1.25},
    "shuffle_yolov3": {"size_mb": 45.5, "mAP": 70.8, "fps_cpu": 4.0},
}
SIZE_RATIO = 0.187  # Sec. 4: "only 18.7% of the model size of YOLOv3"
# Table 3: mAP@0.5 (VOC 07+12 training; YOLOv3's VOC row is third-party, 07+12+COCO)
TABLE3 = {
    "yolov3_darknet53": {"voc2012": None, "voc2007": 85.5, "coco50": 55.3},
    "shuffle_yolov3": {"voc2012": 81.8, "voc2007": 82.6, "coco50": 52.0},
    "ssd321_vgg": {"voc2012": 74.9, "voc2007": 76.8, "coco50": 45.4},
}
# Table 4: inference latency in ms (ARM Cortex-A72 1.8 GHz and Intel i7 3.0 GHz single-thread, 1080Ti)
TABLE4 = {
    "yolov3_darknet53": {"arm_a72": 1500.0, "cpu_i7": 800.0, "gpu_1080ti": 33.0},
    "shuffle_yolov3": {"arm_a72": 500.0, "cpu_i7": 250.0, "gpu_1080ti": 16.7},
}
# Sec. 3.4: memory by the paper's formula (params C_in C_out K^2 + C_out, outputs C_out H W, fp32),
# one 416 x 416 image: about 220 MB for Shuffle-YOLOv3, 48.8 % of YOLOv3 (-> YOLOv3 about 451 MB)
MEMORY_MB = {"shuffle_yolov3": 220.0}
MEMORY_RATIO = 0.488
MEMORY_MB["yolov3_darknet53"] = round(MEMORY_MB["shuffle_yolov3"] / MEMORY_RATIO, 1)  # implied: 450.8

# darknet's own counts of yolov3-voc.cfg (20 classes) at 416, reproduced exactly by our trace
DARKNET_YOLOV3_VOC = {"params": 61_626_049, "bn_moving_stats": 52_608, "bflops": 65.428, "macs": 32_713_987_072}
DARKNET_YOLOV3_COCO = {"params": 61_949_149, "weights_file_bytes": 248_007_048, "bflops": 65.864}
QUOTED_BFLOPS = 65.9  # the figure usually quoted for YOLOv3 at 416 (80 classes)
