"""Starting or attaching to Ray for a search: the environment it runs in and its authentication.

Ray's GCS server, raylet and workers listen on every interface of the machine (binding them to
loopback is not an option Ray offers: `_node_ip_address="127.0.0.1"` leaves the bind as it is), so
the private local Ray a search starts keeps Ray's token authentication on, with a fresh random
token of its own: it is handed to the cluster's processes (the driver, GCS, raylet, workers) in
their environment (RAY_AUTH_TOKEN, readable only by this user), is never written to a file and is
gone from this process when the session ends. Another process, local or remote, that does not
hold the token cannot connect or submit work. A cluster at `--address` is the user's: its
authentication is whatever the user set (RAY_AUTH_MODE and a token, Ray's own variables), and
so is a local Ray's where the user set any of them.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

AUTH_VARIABLES = ("RAY_AUTH_MODE", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH")  # Ray's own, read by its C++ core


def ray_environment(address: str | None, environ: Mapping[str, str]) -> dict[str, str]:
    """Variables to add to `environ` for ray.init: no usage statistics, and for the private local
    Ray (address None) token authentication with a fresh token. A value the user set is never
    overridden, and any authentication variable the user set leaves authentication to them."""
    extra = {"RAY_USAGE_STATS_ENABLED": "0"}
    if address is None and not any(name in environ for name in AUTH_VARIABLES):
        extra.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))
    return {k: v for k, v in extra.items() if k not in environ}


def _reload_ray_authentication() -> None:
    """Make this process's Ray read its authentication settings from the environment again: its
    core reads RAY_AUTH_MODE when ray is imported and caches the token it loads first, so a
    session started after `import ray` (or after another session) would otherwise talk to its own
    cluster with the old mode or token. Config first, as Ray's own test utilities do: a core
    thread still shutting down must not reload a token the mode no longer asks for."""
    from ray._raylet import AuthenticationTokenLoader, Config

    Config.initialize("")
    AuthenticationTokenLoader.instance().reset_cache()


@contextmanager
def ray_session_environment(address: str | None) -> Iterator[None]:
    """os.environ plus `ray_environment(address)` for the block, Ray's authentication reloaded on
    entry and exit, so that a later session in this process (another local Ray, or a remote
    cluster) inherits neither this one's settings nor its token."""
    extra = ray_environment(address, os.environ)
    os.environ.update(extra)
    _reload_ray_authentication()
    try:
        yield
    finally:
        for key in extra:
            os.environ.pop(key, None)
        _reload_ray_authentication()


@contextmanager
def ray_session(address: str | None, num_cpus: int | None = None) -> Iterator[dict]:
    """ray.init in `ray_session_environment(address)`: a fresh private local Ray with `num_cpus`
    CPUs (address None: "local" never attaches to a cluster found through RAY_ADDRESS), or the
    cluster at `address`; ray.shutdown on exit. Yields Ray's address info (gcs_address, ...)."""
    import ray

    with ray_session_environment(address):
        context = ray.init(address=address or "local", include_dashboard=False, log_to_driver=False,
                           **({} if address else {"num_cpus": num_cpus}))
        try:
            yield context.address_info
        finally:
            ray.shutdown()
