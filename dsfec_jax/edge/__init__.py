"""The edge device: detector, depth and placement per frame, and the uplink to the map service."""
