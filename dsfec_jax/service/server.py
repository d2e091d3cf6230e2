"""Run the map service with uvicorn (one process, asyncio + h11; endpoints in its thread pool)."""

from __future__ import annotations

from pathlib import Path

import uvicorn

from .app import create_app


def serve(db_path: str | Path, host: str = "127.0.0.1", port: int = 8000, log_level: str = "info",
          synchronous: str = "FULL") -> None:
    """Serve the database at `db_path` on host:port until interrupted (SIGINT/SIGTERM: graceful).
    synchronous="FULL" acknowledges a batch once fsynced; "NORMAL" is faster, safe against a killed
    server but not against a power loss (store.py)."""
    uvicorn.run(create_app(db_path, synchronous), host=host, port=port, log_level=log_level,
                access_log=log_level in ("debug", "trace"))
