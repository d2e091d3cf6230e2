"""`python -m dsfec_jax.service --db PATH [--host H] [--port P]`: the map service without the CLI
(the load test starts it this way, light: no jax import)."""

import argparse

from .server import serve


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.service", description=__doc__)
    p.add_argument("--db", required=True, help="SQLite database file (created if missing)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug", "trace"])
    p.add_argument("--synchronous", default="FULL", choices=["FULL", "NORMAL"],
                   help="FULL: a batch is fsynced before its 201 (survives a power loss); NORMAL: faster, "
                        "survives a killed server but may lose the last batches on a power loss")
    a = p.parse_args(argv)
    serve(a.db, a.host, a.port, a.log_level, a.synchronous)


if __name__ == "__main__":
    main()
