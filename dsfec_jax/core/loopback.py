"""Whether a host name stays on this machine: the map service binds and answers by it, and the
edge device warns when a token would leave it in clear text. Both sides share this one rule
(they meet only over HTTP, so it lives here, not in either)."""

from __future__ import annotations

import ipaddress

LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")


def is_loopback(host: str) -> bool:
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
