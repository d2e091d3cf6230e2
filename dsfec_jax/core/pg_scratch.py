"""A throw-away schema in a PostgreSQL database: the map service's load test and tests each get
their own (created empty, dropped after), so runs that share one database never see each other's
rows. The service builds its tables in the connection's search_path (service/pg_store.py), which
the returned URL sets. psycopg (the `postgres` extra) loads only when a schema is asked for."""

from __future__ import annotations

import os
import secrets
from contextlib import contextmanager
from urllib.parse import quote


def with_search_path(url: str, schema: str) -> str:
    """`url` with libpq's options parameter naming `schema` as the search path."""
    if "options=" in url:
        raise ValueError(f"{url}: already sets libpq options; give a URL without ?options= (the schema is set through it)")
    return f"{url}{'&' if '?' in url else '?'}options={quote(f'-csearch_path={schema}')}"


@contextmanager
def scratch_schema(url: str, prefix: str = "scratch"):
    """`with scratch_schema(url) as schema_url:` a new empty schema, dropped with its tables on exit."""
    import psycopg

    schema = f"{prefix}_{os.getpid()}_{secrets.token_hex(4)}"
    scoped = with_search_path(url, schema)  # checked before anything is created
    with psycopg.connect(url, autocommit=True, connect_timeout=10) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    try:
        yield scoped
    finally:
        with psycopg.connect(url, autocommit=True, connect_timeout=10) as conn:
            conn.execute(f'DROP SCHEMA "{schema}" CASCADE')
