"""The map service's command line, shared by `dsfec serve` and `python -m dsfec_jax.service`:

    dsfec serve --db map.sqlite [--host 127.0.0.1 --port 8000 --synchronous FULL --log-level info]
    dsfec serve --db postgresql://USER@HOST/DB --workers 4    # PostgreSQL (the `postgres` extra)
    dsfec serve token add --db map.sqlite --device cam-01      # prints the new token once
    dsfec serve token add --db map.sqlite --role read|admin
    dsfec serve token list --db map.sqlite
    dsfec serve token revoke --db map.sqlite ID

argparse only at import (the CLI builds every command's parser on start); the server's modules
load when a command runs. Token commands work on the database directly (the SQLite file: run them on the
server's machine; a running server sees a new or revoked token on its next request).
"""

from __future__ import annotations

import argparse
import json
import sys

LOG_LEVELS = ("critical", "error", "warning", "info", "debug", "trace")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The server's options on `p`, and the optional `token` admin command under it."""
    p.add_argument("--db", help="SQLite database file (created if missing), or a PostgreSQL URL "
                                "postgresql://USER[:PASSWORD]@HOST[:PORT]/DB[?options] (its tables are created if missing)")
    p.add_argument("--workers", type=int, default=1,
                   help="server processes sharing the port (PostgreSQL only: SQLite takes one writer)")
    p.add_argument("--host", default="127.0.0.1",
                   help="interface to bind (default loopback only; 0.0.0.0 listens on every interface: see README)")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--log-level", default="info", choices=LOG_LEVELS)
    p.add_argument("--no-access-log", dest="access_log", action="store_false", help="no line per request")
    p.add_argument("--synchronous", default="FULL", choices=["FULL", "NORMAL"],
                   help="FULL: a batch is fsynced before its 201 (survives a power loss); NORMAL: faster, "
                        "survives a killed server but may lose the last batches on a power loss")
    p.add_argument("--no-auth", action="store_true",
                   help="accept posts without a device token (local experiments; loopback --host only)")
    p.add_argument("--reads", default="auto", choices=["auto", "open", "token"],
                   help="GET /objects, /tracks: open, or a read/admin token; auto = open on a loopback bind only")
    p.add_argument("--allowed-host", action="append", default=[], metavar="NAME",
                   help="a Host header name to serve besides localhost/127.0.0.1/::1 and --host (repeatable; "
                        "the name clients use, e.g. map.example.org; '*' turns the check off)")
    p.add_argument("--docs", action="store_true", help="serve /docs, /redoc, /openapi.json (their pages load a CDN)")
    p.add_argument("--retention-days", type=float, default=None,
                   help="delete batches older than this many days (by batch time), hourly")
    p.add_argument("--ssl-keyfile", default=None, help="TLS: the private key (PEM); with --ssl-certfile")
    p.add_argument("--ssl-certfile", default=None, help="TLS: the certificate chain (PEM)")
    admin = p.add_subparsers(dest="admin", metavar="{token}", help="admin commands (optional)")
    t = admin.add_parser("token", help="issue, list or revoke access tokens")
    actions = t.add_subparsers(dest="token_action", required=True)
    add = actions.add_parser("add", help="issue a token and print it (it is not stored: keep it)")
    add.add_argument("--db", required=True)
    add.add_argument("--role", default="device", choices=["device", "read", "admin"])
    add.add_argument("--device", action="append", default=[],
                     help="role device: the device name the token posts for (repeatable: one token each)")
    add.add_argument("--json", action="store_true", help="print [{id, role, device, token}, ...]")
    lst = actions.add_parser("list", help="token ids, roles, devices, revocations (never the tokens)")
    lst.add_argument("--db", required=True)
    rev = actions.add_parser("revoke", help="revoke a token by its id")
    rev.add_argument("--db", required=True)
    rev.add_argument("id")


def run(args, prog: str) -> int:
    """Run the server or an admin command from parsed `args`."""
    if not args.db:
        sys.exit(f"{prog}: --db PATH is required")
    if args.admin == "token":
        return _token_command(args, prog)
    from .server import resolve_access, serve

    if bool(args.ssl_keyfile) != bool(args.ssl_certfile):
        sys.exit(f"{prog}: --ssl-keyfile and --ssl-certfile go together")
    try:
        access = resolve_access(args.host, args.no_auth, args.reads, args.allowed_host, args.docs, args.retention_days)
        serve(args.db, args.host, args.port, args.log_level, args.synchronous, access, args.access_log,
              args.ssl_keyfile, args.ssl_certfile, args.workers)
    except ValueError as err:
        sys.exit(f"{prog}: {err}")
    return 0


def _token_command(args, prog: str) -> int:
    from . import tokens
    from .store import open_store

    try:
        store = open_store(args.db)
    except ValueError as err:
        sys.exit(f"{prog} token: {err}")
    try:
        if args.token_action == "list":
            print(json.dumps(tokens.listing(store), indent=1))
        elif args.token_action == "revoke":
            if not tokens.revoke(store, args.id):
                sys.exit(f"{prog} token revoke: no live token with id {args.id!r} in {store.name}")
            print(f"revoked {args.id}")
        else:
            issued = [dict(zip(("id", "token"), tokens.issue(store, args.role, device)), role=args.role, device=device)
                      for device in (args.device or [None])]
            if args.json:
                print(json.dumps(issued, indent=1))
            else:
                for item in issued:
                    print(item["token"])
                print(f"({len(issued)} {args.role} token{'s' if len(issued) > 1 else ''} issued, "
                      f"ids {', '.join(i['id'] for i in issued)}: shown once, only their hashes are stored)",
                      file=sys.stderr)
    except ValueError as err:
        sys.exit(f"{prog} token {args.token_action}: {err}")
    finally:
        store.close()
    return 0
