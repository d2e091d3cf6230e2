"""Box coders, geometry (corners, point-in-box, rotated IoU) and NMS on numpy/JAX arrays."""
