"""Point-cloud frames: the Frame schema, synthetic radar, real-format readers (nuScenes, VoD,
TJ4DRadSet), augmentation and pillarization."""
