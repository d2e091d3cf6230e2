""".ci/postgres, the throw-away PostgreSQL server of CI (.ci/run starts it and sets
DSFEC_TEST_POSTGRES; every PostgreSQL test runs on it): it opens no TCP port, refuses a folder that
is not fresh, and `stop` leaves nothing behind."""

from __future__ import annotations

import glob
import subprocess
from pathlib import Path

import pytest

from stores import postgres_url

SCRIPT = Path(__file__).resolve().parents[2] / ".ci" / "postgres"


def test_the_ci_server_opens_no_tcp_port():
    import psycopg

    url = postgres_url()
    if "host=/" not in url:
        pytest.skip(f"{url} is not a server of .ci/postgres (those listen on a unix socket folder only)")
    with psycopg.connect(url) as conn:
        assert conn.execute("SHOW listen_addresses").fetchone()[0] == ""
        assert url.endswith("host=" + conn.execute("SHOW unix_socket_directories").fetchone()[0])


@pytest.mark.skipif(not glob.glob("/usr/lib/postgresql/*/bin/postgres"),
                    reason="no PostgreSQL server binaries here (.ci/run installs Debian's package)")
def test_start_refuses_a_used_folder_and_stop_removes_it(tmp_path):
    (tmp_path / "left-over").write_text("an earlier run's")
    again = subprocess.run([str(SCRIPT), "start", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert again.returncode != 0 and "not empty" in again.stderr
    subprocess.run([str(SCRIPT), "stop", str(tmp_path)], capture_output=True, timeout=60, check=True)
    assert not tmp_path.exists()
