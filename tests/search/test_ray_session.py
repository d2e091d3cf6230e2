"""The private local Ray a search starts keeps token authentication on, with a fresh token of its
own (search/ray_session.py): a process without the token cannot connect to it, over the
machine's own address, while one with it can run a task; a cluster at --address is left to the
user's settings, and nothing of a session stays in the environment afterwards."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

ray = pytest.importorskip("ray")

from search import runners  # noqa: E402
from search.ray_session import AUTH_VARIABLES, ray_session  # noqa: E402

# a client of the cluster at argv[1]: runs one task and prints its result
CLIENT = """
import sys
import ray
ray.init(address=sys.argv[1], log_to_driver=False)
print("task ran:", ray.get(ray.remote(lambda: 6 * 7).remote(), timeout=60))
"""


def client(gcs_address: str, token: str | None) -> subprocess.CompletedProcess:
    """CLIENT in a separate process, with the token or without any (then one connection attempt
    instead of Ray's 20 one-second retries: a refusal is final)."""
    env = {k: v for k, v in os.environ.items() if k not in AUTH_VARIABLES and k != "RAY_ADDRESS"}
    env.update({"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": token} if token else {"RAY_gcs_server_port_wait_time_s": "1"})
    return subprocess.run([sys.executable, "-c", CLIENT, gcs_address], env=env, capture_output=True, text=True,
                          timeout=120)


def test_a_process_without_the_token_cannot_use_the_local_ray(monkeypatch):
    for name in (*AUTH_VARIABLES, "RAY_ADDRESS"):
        monkeypatch.delenv(name, raising=False)
    assert not ray.is_initialized()
    with ray_session(None, num_cpus=1) as info:
        token = os.environ["RAY_AUTH_TOKEN"]
        gcs = info["gcs_address"]  # the machine's address, not loopback: what another host would reach
        assert ray.get(ray.remote(lambda: 1).remote(), timeout=60) == 1  # the driver's own work runs
        refused = client(gcs, None)
        assert refused.returncode != 0 and "task ran" not in refused.stdout
        assert "InvalidAuthToken" in refused.stderr or "Authentication" in refused.stderr, refused.stderr[-2000:]
        allowed = client(gcs, token)  # the same client with the token: the refusal above was the token's
        assert "task ran: 42" in allowed.stdout, allowed.stderr[-2000:]
    assert not ray.is_initialized()
    assert not any(name in os.environ for name in AUTH_VARIABLES)  # the token went with the session


class _RayInitReached(Exception):
    pass


@pytest.mark.parametrize("address", ["ray://host:10001", "10.0.0.5:6379", None])
def test_only_the_local_ray_gets_a_fresh_token_and_the_users_settings_win(tmp_path, monkeypatch, address):
    seen = []

    def fake_init(**kwargs):  # what ray.init would see; no cluster is started or reached
        seen.append({**kwargs, **{name: os.environ.get(name) for name in AUTH_VARIABLES}})
        raise _RayInitReached

    for name in AUTH_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", fake_init)
    todo = [{"key": "k", "label": "x", "seed": 0}]
    for _ in range(2):
        with pytest.raises(_RayInitReached):
            runners.run_ray(todo, tmp_path, address=address, log=lambda _: None)
    assert all(s["address"] == (address or "local") for s in seen)
    if address is None:  # token auth, a new token each time
        assert [s["RAY_AUTH_MODE"] for s in seen] == ["token", "token"]
        assert all(len(s["RAY_AUTH_TOKEN"]) == 64 for s in seen) and seen[0]["RAY_AUTH_TOKEN"] != seen[1]["RAY_AUTH_TOKEN"]
    else:  # a remote cluster's authentication is the user's (Ray's own default applies)
        assert all(s[name] is None for s in seen for name in AUTH_VARIABLES)
    assert not any(name in os.environ for name in AUTH_VARIABLES)  # nothing leaks into a later run
    monkeypatch.setenv("RAY_AUTH_MODE", "disabled")  # the user's explicit choice wins, local or remote
    with pytest.raises(_RayInitReached):
        runners.run_ray(todo, tmp_path, address=address, log=lambda _: None)
    assert seen[-1]["RAY_AUTH_MODE"] == "disabled" and seen[-1]["RAY_AUTH_TOKEN"] is None
