"""Training: losses, schedules, the jitted step, the loop, checkpoints."""
