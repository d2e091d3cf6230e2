"""Camera images: the PASCAL VOC reader and the embedded street-scene benchmark (street/)."""
