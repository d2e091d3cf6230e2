"""Depth metrics: they judge depth maps and per-object depths, whoever estimated them."""
