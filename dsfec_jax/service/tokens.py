"""Access tokens of the map service: issued by the operator, sent as `Authorization: Bearer <token>`.

Roles: "device" (bound to one device name: may POST that device's batches, nothing else), "read"
(GET the map's data when reads need a token) and "admin" (read, delete, export). A token is
"dsfec_<id>_<secret>": the id is public (listed, revoked by it), the secret is 32 random bytes
(secrets.token_urlsafe). The database holds only sha256(token): a copy of the database file gives
no token. A presented token is looked up by its id and its hash compared in constant time
(hmac.compare_digest), so the answer's timing says nothing about how much of a guess was right.
Revocation is a row update: the next request sees it (no cache).
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import time
from dataclasses import dataclass

ROLES = ("device", "read", "admin")
PREFIX = "dsfec"


@dataclass(frozen=True)
class Principal:
    """Who a valid token speaks for."""
    token_id: str
    role: str
    device: str | None

    def may_read(self) -> bool:
        return self.role in ("read", "admin")


def _digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def issue(store, role: str, device: str | None = None) -> tuple[str, str]:
    """A new token for `role` (and `device` for role "device"). Returns (id, token); the token is
    shown to the operator once and never stored."""
    if role not in ROLES:
        raise ValueError(f"role {role!r}; expected one of {ROLES}")
    if (role == "device") != bool(device and device.strip()):
        raise ValueError("a device token needs --device NAME; read and admin tokens take none")
    if device is not None and len(device) > 256:
        raise ValueError("device: at most 256 characters (the batch schema's bound)")
    token_id = secrets.token_hex(6)
    token = f"{PREFIX}_{token_id}_{secrets.token_urlsafe(32)}"
    with store.transaction() as tx:
        tx.execute("INSERT INTO tokens (id, sha256, role, device, created) VALUES (?, ?, ?, ?, ?)",
                   (token_id, _digest(token), role, device, time.time()))
    return token_id, token


def revoke(store, token_id: str) -> bool:
    """Revoke a token by its id; False when no live token has that id."""
    with store.transaction() as tx:
        return tx.execute("UPDATE tokens SET revoked = ? WHERE id = ? AND revoked IS NULL",
                          (time.time(), token_id)).rowcount == 1


def listing(store) -> list[dict]:
    rows = store.snapshot_rows("SELECT id, role, device, created, revoked FROM tokens ORDER BY created")
    return [dict(zip(("id", "role", "device", "created", "revoked"), r)) for r in rows]


def authenticate(store, authorization: str | None) -> Principal | None:
    """The principal of an `Authorization: Bearer <token>` header value, or None when it is
    missing, malformed, unknown or revoked."""
    scheme, _, token = (authorization or "").partition(" ")
    token = token.strip()
    if scheme.lower() != "bearer" or not token:
        return None
    prefix, _, rest = token.partition("_")
    token_id, _, secret = rest.partition("_")
    if prefix != PREFIX or not token_id or not secret or len(token) > 200:
        return None
    rows = store.snapshot_rows("SELECT sha256, role, device FROM tokens WHERE id = ? AND revoked IS NULL", (token_id,))
    if not rows or not hmac.compare_digest(rows[0][0], _digest(token)):
        return None
    return Principal(token_id, rows[0][1], rows[0][2])
