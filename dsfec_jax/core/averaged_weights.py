"""Which weights a training checkpoint stands for: its weight average's, where it keeps one.

A run that trains with a weight EMA (train/ema.py) keeps the average beside the raw weights in
its state, under EMA_KEY: {'params', 'batch_stats', 'updates'}. The average is what the run
validates, so it is also what `dsfec ship`, `--weights` and a warm start read from such a
checkpoint, as ultralytics loads a checkpoint's 'ema' before its 'model'. This sits in core
because zoo (which loads weights) may not import train.
"""

from __future__ import annotations

EMA_KEY = "ema"


def weights_of(tree: dict) -> dict:
    """The tree holding the checkpoint's weights: its EMA entry when it has one, else itself."""
    average = tree.get(EMA_KEY)
    return average if isinstance(average, dict) else tree
