"""The HTTP routes of the map service (FastAPI).

  POST   /detections  one frame batch (schema.FrameBatch), with a device token for the batch's
                      device. 201 stored, 200 duplicate (same id, same content: a device's retry),
                      409 conflict (same id, other content), 422 when the body breaks the schema
                      ("objects.2.lat: ..."; nothing stored), 401 without a valid token (header
                      WWW-Authenticate: Bearer), 403 for a token of another device or role,
                      413 / 408 / 400 for an oversized, slow or ambiguous body (guards.py).
  GET    /objects     ?bbox=minlon,minlat,maxlon,maxlat&since=<UNIX s | ISO 8601>&limit=N: the latest
                      objects (newest first) as a GeoJSON FeatureCollection; &after=CURSOR: those
                      stored since an earlier answer's "cursor" instead (oldest first). "truncated"
                      says whether `limit` cut it. Bad parameters get a 400 naming the parameter.
  GET    /tracks      ?since=&device=&max_points=N: one Feature per device: a LineString of its ego
                      positions in time order, at most N per device, evenly spread (a Point for a
                      device seen once); &after=CURSOR: only the positions stored since.
  DELETE /detections  ?device=&since=&until= (admin): delete batches and their objects.
  GET    /export      ?device=&since=&until= (admin): the batches as JSON lines, exchange format.
  GET    /health      liveness and counts (always open; O(1) in the stored rows).
  GET    /            the map page (static/map.html, drawn offline on a canvas); open, it holds no data.

Reads (/objects, /tracks) are open or need a read/admin token (Access.open_reads; server.py picks
open only on a loopback bind). Writes need a device token unless Access.write_auth is off.

Endpoints that touch the database run in FastAPI's thread pool, so a slow commit (an fsync) blocks
one worker thread, not the event loop. The store gives each thread its connection (SQLite) or
lends it one from its pool (PostgreSQL).
"""

from __future__ import annotations

import asyncio
import datetime as dt
import json
import logging
import math
import time
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path

from fastapi import Depends, FastAPI, HTTPException, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, StreamingResponse
from fastapi.staticfiles import StaticFiles
from pydantic import ValidationError

from ..geo.geojson import feature_collection, object_features, track_features
from . import tokens
from ..core.loopback import LOOPBACK_NAMES
from .guards import BodyGuard, HostAllowList
from .schema import FrameBatch, field_errors
from .sql_store import Conflict, SqlStore
from .store import open_store

STATIC = Path(__file__).resolve().parent / "static"
MAX_BODY_BYTES = 2 * 1024 * 1024  # a full batch of MAX_OBJECTS objects is ~0.3 MB
MAX_LIMIT = 50_000
MAX_TRACK_POINTS = 20_000
log = logging.getLogger("uvicorn.error")  # uvicorn configures it: our lines share its format


@dataclass(frozen=True)
class Access:
    """Who may do what, and what the server accepts (docs/edge-and-map-service.md, "Map service":
    the defaults are safe)."""
    write_auth: bool = True            # POST needs a device token of the batch's device
    open_reads: bool = True            # GET /objects, /tracks without a token (server.py: loopback only)
    allowed_hosts: tuple[str, ...] = LOOPBACK_NAMES
    docs: bool = False                 # /docs, /redoc, /openapi.json (they load scripts from a CDN)
    body_timeout_s: float = 30.0       # a whole request body must arrive within this
    retention_days: float | None = None  # delete batches older than this (by their time), periodically
    retention_every_s: float = 3600.0


def create_app(db_path: str | Path, synchronous: str = "FULL", access: Access = Access()) -> FastAPI:
    """The service over the database `db_path`: a SQLite file (created if missing) or a
    postgresql:// URL (store.open_store). `synchronous`: "FULL" acknowledges a batch once it is on
    disk, "NORMAL" once a killed service cannot lose it (store.py, pg_store.py). `access`:
    authentication, hosts, docs, limits."""
    store = open_store(db_path, synchronous)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        if not access.write_auth:
            log.warning("write authentication is OFF (--no-auth): anyone who reaches the port can post as any device")
        elif not any(t["role"] == "device" and t["revoked"] is None for t in tokens.listing(store)):
            log.warning("no device token issued yet: every post will be refused (401); issue one with "
                        "`dsfec serve token add --db %s --device NAME`", store.name)
        sweeper = asyncio.create_task(_retention(store, access)) if access.retention_days else None
        yield
        if sweeper is not None:
            sweeper.cancel()
        store.close()

    docs = {} if access.docs else {"docs_url": None, "redoc_url": None, "openapi_url": None}
    app = FastAPI(title="dsfec map service", lifespan=lifespan, **docs)
    app.state.store = store
    app.add_middleware(BodyGuard, max_bytes=MAX_BODY_BYTES, body_timeout_s=access.body_timeout_s)
    app.add_middleware(HostAllowList, allowed=access.allowed_hosts)  # added last: runs first
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    def reader(request: Request) -> None:
        if not access.open_reads:
            _principal(store, request, lambda p: p.may_read(), "reading needs a read or admin token")

    def admin(request: Request) -> None:
        _principal(store, request, lambda p: p.role == "admin", "this needs an admin token")

    @app.post("/detections", status_code=201)
    async def post_detections(request: Request) -> JSONResponse:
        authorization = request.headers.get("authorization")
        body = await request.body()  # BodyGuard read it already, bounded
        status, reply = await run_in_threadpool(_accept, store, access, authorization, body)
        return JSONResponse(reply, status_code=status, headers=_CHALLENGE if status == 401 else None)

    @app.get("/objects", dependencies=[Depends(reader)])
    def get_objects(bbox: str | None = None, since: str | None = None,
                    limit: int = Query(5000, ge=1, le=MAX_LIMIT), after: int | None = Query(None, ge=0)) -> dict:
        batches, truncated, cursor = store.objects(parse_bbox(bbox), parse_since(since), limit, after)
        features = [f for b in batches for f in object_features(b)]
        return {**feature_collection(features), "truncated": truncated, "cursor": cursor}

    @app.get("/tracks", dependencies=[Depends(reader)])
    def get_tracks(since: str | None = None, device: str | None = None, after: int | None = Query(None, ge=0),
                   max_points: int = Query(2000, ge=2, le=MAX_TRACK_POINTS)) -> dict:
        tracks, cursor = store.tracks(parse_since(since), device, max_points, after)
        return {**feature_collection(track_features(tracks)), "cursor": cursor}

    @app.delete("/detections", dependencies=[Depends(admin)])
    def delete_detections(device: str | None = None, since: str | None = None, until: str | None = None) -> dict:
        if device is None and not since and not until:
            raise HTTPException(400, detail="give device, since and/or until (to delete everything: since=0)")
        deleted = store.delete(device, parse_since(since, "since"), parse_since(until, "until"))
        log.warning("deleted %s (device=%s since=%s until=%s)", deleted, device, since, until)
        return {"deleted": deleted}

    @app.get("/export", dependencies=[Depends(admin)])
    def export(device: str | None = None, since: str | None = None, until: str | None = None) -> StreamingResponse:
        batches = store.export(device, parse_since(since, "since"), parse_since(until, "until"))
        lines = (json.dumps(b, separators=(",", ":")) + "\n" for b in batches)
        return StreamingResponse(lines, media_type="application/x-ndjson")

    @app.get("/health")
    def health() -> dict:
        return {"status": "ok", "store": store.kind, "journal_mode": store.journal_mode(), "synchronous": store.synchronous,
                "write_auth": access.write_auth, "open_reads": access.open_reads, **store.counts()}

    @app.get("/", include_in_schema=False)
    def map_page() -> FileResponse:
        return FileResponse(STATIC / "map.html", media_type="text/html")

    return app


_CHALLENGE = {"WWW-Authenticate": "Bearer"}


def _principal(store: SqlStore, request: Request, allowed, refusal: str) -> tokens.Principal:
    principal = tokens.authenticate(store, request.headers.get("authorization"))
    if principal is None:
        raise HTTPException(401, detail="a valid token is required (Authorization: Bearer <token>)", headers=_CHALLENGE)
    if not allowed(principal):
        raise HTTPException(403, detail=f"{refusal}; this is a {principal.role} token")
    return principal


def _accept(store: SqlStore, access: Access, authorization: str | None, body: bytes) -> tuple[int, dict]:
    """POST /detections in the thread pool: authenticate, validate, store -> (status, reply).
    Authentication comes first: without a token nothing about the body is answered."""
    principal = tokens.authenticate(store, authorization) if access.write_auth else None
    if access.write_auth and principal is None:
        return 401, {"detail": "a device token is required (Authorization: Bearer <token>)"}
    if principal is not None and principal.role != "device":
        return 403, {"detail": f"only a device token may post; this is a {principal.role} token"}
    try:
        data = json.loads(body)
    except json.JSONDecodeError as e:
        return 422, _errors([f"body: not valid JSON at character {e.pos} ({e.msg})"])
    except (ValueError, RecursionError) as e:  # not UTF-8, a 5000-digit number, [[[[... nested too deep
        return 422, _errors([f"body: not valid JSON ({type(e).__name__}: {str(e)[:200]})"])
    try:
        batch = FrameBatch.model_validate(data)
    except ValidationError as e:
        return 422, _errors(field_errors(e.errors(), drop_prefix=()))
    if principal is not None and batch.device != principal.device:
        return 403, {"detail": f"device: this token posts for device {principal.device!r}, not {batch.device!r}"}
    try:
        outcome = store.put(batch)
    except Conflict as e:
        return 409, {"detail": str(e)}
    reply = {"status": outcome, "batch_id": batch.batch_id, "objects": len(batch.objects)}
    return (201 if outcome == "stored" else 200), reply


def _errors(lines: list[str]) -> dict:
    return {"detail": "; ".join(lines), "errors": lines}


async def _retention(store: SqlStore, access: Access) -> None:
    """Every retention_every_s: delete batches older than retention_days (store.delete works in
    bounded transactions, so posts go on meanwhile)."""
    while True:
        cutoff = time.time() - access.retention_days * 86400.0
        try:
            deleted = await run_in_threadpool(store.delete, None, None, cutoff)
            if deleted["batches"]:
                log.info("retention: deleted %s older than %s days", deleted, access.retention_days)
        except Exception:  # a failed sweep (disk full, locked) must not stop the service or later sweeps
            log.exception("retention sweep failed")
        await asyncio.sleep(access.retention_every_s)


def parse_bbox(text: str | None) -> tuple[float, float, float, float] | None:
    if text is None or text == "":
        return None
    expected = "expected minlon,minlat,maxlon,maxlat in WGS84 degrees"
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise HTTPException(400, detail=f"bbox: {expected}, got {text!r}") from None
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise HTTPException(400, detail=f"bbox: {expected} (4 finite numbers), got {text!r}")
    minlon, minlat, maxlon, maxlat = values
    if not (-180 <= minlon <= 180 and -180 <= maxlon <= 180 and -90 <= minlat <= maxlat <= 90):
        raise HTTPException(400, detail=f"bbox: {expected} with lon in [-180, 180], lat in [-90, 90] and "
                                        f"minlat <= maxlat, got {text!r}")
    return minlon, minlat, maxlon, maxlat


def parse_since(text: str | None, name: str = "since") -> float | None:
    """UNIX seconds, or an ISO 8601 time (one without a zone is read as UTC) -> UNIX seconds."""
    if text is None or text == "":
        return None
    try:
        value = float(text)
    except ValueError:
        try:
            when = dt.datetime.fromisoformat(text)
        except ValueError:
            raise HTTPException(400, detail=f"{name}: expected UNIX seconds or an ISO 8601 time "
                                            f"(e.g. 2026-11-25T04:25:00Z), got {text!r}") from None
        return (when if when.tzinfo else when.replace(tzinfo=dt.timezone.utc)).timestamp()
    if not math.isfinite(value):
        raise HTTPException(400, detail=f"{name}: expected a finite number of UNIX seconds, got {text!r}")
    return value


async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
    """FastAPI's 422 with the fields spelled "objects.2.lat: ..."; a bad query parameter is a 400."""
    errors = exc.errors()
    in_query = all(err.get("loc", ("body",))[0] in ("query", "path") for err in errors)
    lines = field_errors(errors, drop_prefix=("query",) if in_query else ("body",))
    return JSONResponse(_errors(lines), status_code=400 if in_query else 422)
