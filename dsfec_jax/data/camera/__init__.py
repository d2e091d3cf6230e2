"""Camera images: the PASCAL VOC reader (voc.py) and the embedded street-scene benchmark (street/);
images.py (CameraImage: an image with its boxes, whatever the source), sources.py (named sources ->
images, class maps between sources), letterbox.py (input sizes, the letterbox, one affine warp for
image and boxes), augment.py (HSV, scale / translate, flip) and batches.py (training batches with
multi-scale sizes, a pure function of the step); preview.py (a PNG with boxes)."""
