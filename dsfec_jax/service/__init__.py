"""The map service (the paper's Fig. 2 "server"): edge devices POST one frame batch at a time,
SQLite keeps every placed object once, and GET endpoints serve them as GeoJSON to a map page.

Light on purpose: it imports only core/ and geo.geojson (no jax), so `dsfec serve` starts in about
a second. schema.py validates, store.py persists, app.py routes, server.py runs uvicorn (also
`python -m dsfec_jax.service --db PATH`), static/ holds the map page. The devices' side is edge/:
edge/uplink.py posts through a disk queue, and edge/loadtest.py measures the service under a
fleet of devices and a server kill, talking to it only over HTTP.
"""
