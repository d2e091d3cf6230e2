"""The map service's two stores under the same tests: the fixtures `db` (one test) and `module_db`
(a module's shared server) are a SQLite file, then a fresh schema of the PostgreSQL database that
DSFEC_TEST_POSTGRES names (.ci/run starts a server and sets it). Without it the PostgreSQL
variants skip, saying why; under CI=true they fail instead, so a CI that lost its server is red.
A test module imports the fixtures it uses (`from stores import db`): a conftest.py here would
shadow tests/conftest.py for the modules that `from conftest import ...`."""

from __future__ import annotations

import contextlib
import os

import pytest

from dsfec_jax.core.pg_scratch import scratch_schema

POSTGRES_ENV = "DSFEC_TEST_POSTGRES"
STORES = ("sqlite", "postgres")


def postgres_url() -> str:
    """The test database's URL, or a skip (a failure under CI=true) saying what is missing."""
    url = os.environ.get(POSTGRES_ENV, "")
    reason = None
    if not url:
        reason = f"no PostgreSQL server: set {POSTGRES_ENV}=postgresql://... (.ci/run starts one and sets it)"
    else:
        try:
            import psycopg  # noqa: F401 (only whether the extra is installed)
        except ImportError:
            reason = "psycopg is not installed: pip install -e '.[postgres]'"
    if reason and os.environ.get("CI") == "true":
        pytest.fail(f"CI=true: the PostgreSQL variants must run: {reason}")
    if reason:
        pytest.skip(reason)
    return url


def _database(kind: str, folder):
    if kind == "sqlite":
        return contextlib.nullcontext(folder / "map.sqlite")
    return scratch_schema(postgres_url(), "test")


@pytest.fixture(params=STORES)
def db(request, tmp_path):
    """A new, empty database: a SQLite path or a postgresql:// URL (open_store takes either)."""
    with _database(request.param, tmp_path) as where:
        yield where


@pytest.fixture(scope="module", params=STORES)
def module_db(request, tmp_path_factory):
    with _database(request.param, tmp_path_factory.mktemp(request.param)) as where:
        yield where
