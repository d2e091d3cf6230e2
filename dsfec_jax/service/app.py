"""The HTTP routes of the map service (FastAPI).

  POST /detections   one frame batch (schema.FrameBatch). 201 stored, 200 duplicate (same id, same
                     content: a device's retry), 409 conflict (same id, other content), 422 when the
                     body breaks the schema ("objects.2.lat: ..."; nothing stored), 411/413 when the
                     body has no length or is too large.
  GET  /objects      ?bbox=minlon,minlat,maxlon,maxlat&since=<UNIX s | ISO 8601>&limit=N: the latest
                     objects (newest first) as a GeoJSON FeatureCollection; "truncated" says whether
                     `limit` cut it. Bad parameters get a 400 naming the parameter.
  GET  /tracks       ?since=&device=: one Feature per device: a LineString of its ego positions in
                     time order (a Point for a device seen once; geo.geojson).
  GET  /health       liveness and counts.
  GET  /             the map page (static/map.html, drawn offline on a canvas).

Endpoints are plain `def`: FastAPI runs them in its thread pool, so a slow SQLite commit (an
fsync) blocks one worker thread, not the event loop. The store gives each thread its connection.
"""

from __future__ import annotations

import datetime as dt
import math
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI, HTTPException, Query, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles

from ..geo.geojson import feature_collection, object_features, track_features
from .schema import FrameBatch, field_errors
from .store import Conflict, Store

STATIC = Path(__file__).resolve().parent / "static"
MAX_BODY_BYTES = 2 * 1024 * 1024  # a full batch of MAX_OBJECTS objects is ~0.3 MB
MAX_LIMIT = 50_000


def create_app(db_path: str | Path, synchronous: str = "FULL") -> FastAPI:
    """The service over the SQLite database at `db_path` (created if missing). `synchronous`:
    "FULL" acknowledges a batch once it is fsynced, "NORMAL" once a killed process cannot lose it
    (store.py)."""
    store = Store(db_path, synchronous)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        yield
        store.close()

    app = FastAPI(title="dsfec map service", lifespan=lifespan)
    app.state.store = store
    app.add_middleware(BodyLimit, max_bytes=MAX_BODY_BYTES)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.post("/detections", status_code=201)
    def post_detections(batch: FrameBatch, response: Response) -> dict:
        try:
            outcome = store.put(batch)
        except Conflict as e:
            raise HTTPException(409, detail=str(e)) from None
        if outcome == "duplicate":
            response.status_code = 200
        return {"status": outcome, "batch_id": batch.batch_id, "objects": len(batch.objects)}

    @app.get("/objects")
    def get_objects(bbox: str | None = None, since: str | None = None,
                    limit: int = Query(5000, ge=1, le=MAX_LIMIT)) -> dict:
        batches, truncated = store.objects(parse_bbox(bbox), parse_since(since), limit)
        features = [f for b in batches for f in object_features(b)]
        return {**feature_collection(features), "truncated": truncated}

    @app.get("/tracks")
    def get_tracks(since: str | None = None, device: str | None = None) -> dict:
        return feature_collection(track_features(store.tracks(parse_since(since), device)))

    @app.get("/health")
    def health() -> dict:
        return {"status": "ok", "journal_mode": store.journal_mode(), "synchronous": store.synchronous, **store.counts()}

    @app.get("/", include_in_schema=False)
    def map_page() -> FileResponse:
        return FileResponse(STATIC / "map.html", media_type="text/html")

    return app


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


def parse_since(text: str | None) -> float | None:
    """UNIX seconds, or an ISO 8601 time (one without a zone is read as UTC) -> UNIX seconds."""
    if text is None or text == "":
        return None
    try:
        value = float(text)
    except ValueError:
        try:
            when = dt.datetime.fromisoformat(text)
        except ValueError:
            raise HTTPException(400, detail=f"since: expected UNIX seconds or an ISO 8601 time "
                                            f"(e.g. 2026-11-25T04:25:00Z), got {text!r}") from None
        return (when if when.tzinfo else when.replace(tzinfo=dt.timezone.utc)).timestamp()
    if not math.isfinite(value):
        raise HTTPException(400, detail=f"since: expected a finite number of UNIX seconds, got {text!r}")
    return value


async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
    """FastAPI's 422 with the fields spelled "objects.2.lat: ..."; a bad query parameter is a 400."""
    errors = exc.errors()
    in_query = all(err.get("loc", ("body",))[0] in ("query", "path") for err in errors)
    lines = field_errors(errors, drop_prefix=("query",) if in_query else ("body",))
    return JSONResponse({"detail": "; ".join(lines), "errors": lines}, status_code=400 if in_query else 422)


class BodyLimit:
    """Refuses a POST whose body is too large (413) or has no Content-Length (411) before it is
    read: the batch bound in the schema only applies after the whole body is in memory."""

    def __init__(self, app, max_bytes: int):
        self.app, self.max_bytes = app, max_bytes

    async def __call__(self, scope, receive, send):
        if scope["type"] == "http" and scope["method"] == "POST":
            length = dict(scope["headers"]).get(b"content-length")
            if length is None or not length.isdigit():
                reply = JSONResponse({"detail": "body: a Content-Length header is required"}, status_code=411)
                return await reply(scope, receive, send)
            if int(length) > self.max_bytes:
                reply = JSONResponse({"detail": f"body: {int(length)} bytes, at most {self.max_bytes}"}, status_code=413)
                return await reply(scope, receive, send)
        await self.app(scope, receive, send)
