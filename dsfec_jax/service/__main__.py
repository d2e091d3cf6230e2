"""`python -m dsfec_jax.service --db PATH [options]` / `... token add --db PATH --device NAME`: the
map service without the project's CLI (the load test starts it this way). Options: options.py,
the same as `dsfec serve`."""

import argparse
import sys

from .options import add_arguments, run


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.service", description=__doc__)
    add_arguments(p)
    return run(p.parse_args(argv), p.prog)


if __name__ == "__main__":
    sys.exit(main())
