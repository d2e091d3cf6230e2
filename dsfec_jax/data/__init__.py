"""Frames and where they come from: the schema, synthetic radar, real-format readers, pillarization, targets."""
