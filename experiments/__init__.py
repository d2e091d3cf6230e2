"""One entry per paper table, reproducing it with one command."""
