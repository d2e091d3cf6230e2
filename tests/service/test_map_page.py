"""The map page in a real headless browser (Debian's chromium): it fetches /tracks and /objects,
draws every object and track (the counts it sets on <body>), refreshes on its timer, copes with an
empty database, and its screenshot shows the tracks and class colours (not a blank canvas)."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from map_page import CHROMIUM, body_attributes, bulk_fill, chromium
from service_helpers import LON0, LiveServer, get, make_batch, post

pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason=f"{CHROMIUM} is not installed (Debian package chromium)")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with LiveServer(tmp_path_factory.mktemp("page") / "map.sqlite") as srv:
        for i in range(12):
            assert post(srv.url, make_batch(i, "dev-a", n_objects=3))[0] == 201
            assert post(srv.url, make_batch(i, "dev-b", n_objects=2, lon=LON0 + 0.003))[0] == 201
        assert post(srv.url, make_batch(0, "dev-c", n_objects=1, lon=LON0 - 0.002))[0] == 201  # a single position
        yield srv


def test_the_page_draws_every_object_and_track_and_refreshes(server, tmp_path):
    dom = chromium(server.url + "/", tmp_path / "profile", "--dump-dom").stdout
    attrs = body_attributes(dom)
    assert "error" not in attrs, attrs
    assert attrs["objects"] == str(12 * 3 + 12 * 2 + 1) and attrs["tracks"] == "3"
    assert int(attrs["drawn"]) >= 2  # drawn at load and again on the 3 s refresh (virtual time budget 5 s)
    assert "pedestrian" in dom and "dev-c" in dom  # the legend lists classes and devices


def test_an_empty_database_draws_an_empty_map(tmp_path):
    with LiveServer(tmp_path / "empty.sqlite") as srv:
        attrs = body_attributes(chromium(srv.url + "/", tmp_path / "profile", "--dump-dom").stdout)
    assert attrs["objects"] == "0" and attrs["tracks"] == "0" and int(attrs["drawn"]) >= 1 and "error" not in attrs


def test_the_screenshot_shows_tracks_and_class_colours(server, tmp_path):
    png = tmp_path / "map.png"
    chromium(server.url + "/", tmp_path / "profile", f"--screenshot={png}", "--window-size=1000,700")
    img = np.asarray(Image.open(io.BytesIO(png.read_bytes())).convert("RGB")).astype(int)
    assert img.shape == (700, 1000, 3)
    canvas = img[40:, :780]  # below the header, left of the legend (the page keeps the data clear of it)

    def pixels(hex_colour, tol=40):
        rgb = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)])
        return int((np.abs(canvas - rgb).sum(-1) < tol).sum())

    assert len(np.unique(canvas.reshape(-1, 3), axis=0)) > 50     # not a blank or one-colour canvas
    assert pixels("#2b8a3e") > 300 and pixels("#0b7285") > 300     # the first two devices' track lines
    assert pixels("#1f77b4", 80) > 20 and pixels("#d62728", 80) > 20  # car and pedestrian dots


def test_the_page_draws_a_large_database_within_its_limits(tmp_path):
    """150k frame batches (past the ~125k positions at which spreading a track into Math.min threw
    a RangeError and left the map blank): the page draws the latest OBJECT_LIMIT objects and the
    server-decimated tracks, with no error, and refreshes."""
    bulk_fill(tmp_path / "big.sqlite", 150_000, devices=4, per_batch=1)
    with LiveServer(tmp_path / "big.sqlite") as srv:
        dom = chromium(srv.url + "/", tmp_path / "profile", "--dump-dom", budget_ms=7000).stdout
        tracks = get(srv.url, "/tracks")[1]
    attrs = body_attributes(dom)
    assert "error" not in attrs, attrs
    assert attrs["objects"] == "5000" and attrs["tracks"] == "4" and int(attrs["drawn"]) >= 2
    assert [len(f["geometry"]["coordinates"]) for f in tracks["features"]] == [2000] * 4  # max_points per device


def test_reads_behind_a_token_take_it_from_the_url_fragment_and_a_refusal_shows(tmp_path):
    from dsfec_jax.service import tokens
    from dsfec_jax.service.app import Access
    from dsfec_jax.service.store import Store

    store = Store(tmp_path / "closed.sqlite")
    _, reader = tokens.issue(store, "read")
    store.close()
    with LiveServer(tmp_path / "closed.sqlite", access=Access(write_auth=False, open_reads=False)) as srv:
        assert post(srv.url, make_batch(0, "dev-a", n_objects=2))[0] == 201
        refused = body_attributes(chromium(srv.url + "/", tmp_path / "p1", "--dump-dom", budget_ms=2000).stdout)
        allowed = body_attributes(chromium(srv.url + f"/#token={reader}", tmp_path / "p2", "--dump-dom",
                                           budget_ms=2000).stdout)
    assert "HTTP 401" in refused["error"] and refused["objects"] == "0"  # said on the page, not a silent blank
    assert "error" not in allowed and allowed["objects"] == "2" and allowed["tracks"] == "1"
