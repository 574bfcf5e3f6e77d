"""The token rule: loopback without a token, any other host only with one,
and with a token every request (from loopback too) carries it."""

from __future__ import annotations

import subprocess
import sys

import pytest

from scattertrack.server import auth


@pytest.mark.parametrize("host", ["127.0.0.1", "127.0.0.2", "localhost", "::1", "[::1]"])
def test_loopback_hosts_need_no_token(host):
    assert auth.is_loopback(host)
    assert auth.refusal(host, None) is None


@pytest.mark.parametrize("host", ["0.0.0.0", "::", "192.168.1.20", "myhost.example"])
def test_other_hosts_need_a_token(host):
    assert "--token" in auth.refusal(host, None)
    assert auth.refusal(host, "s3cret") is None


def test_an_empty_token_is_refused():
    assert "empty" in auth.refusal("127.0.0.1", "  ")


def test_any_host_without_a_token_exits_1_at_once():
    env_without_token = {"PATH": "/usr/bin:/bin"}
    result = subprocess.run(
        [sys.executable, "-m", "scattertrack", "dashboard", "--host", "0.0.0.0", "--port", "1"],
        capture_output=True, text=True, timeout=120, env=env_without_token,
    )
    assert result.returncode == 1
    assert "scattertrack: dashboard refused: --host 0.0.0.0" in result.stderr
    assert "--token" in result.stderr and "SCATTERTRACK_TOKEN" in result.stderr


def test_loopback_without_a_token_serves_the_page_and_the_api(serve, get):
    with serve() as url:
        assert get(f"{url}/api/health")[0] == 200
        status, body = get(f"{url}/")
        assert status in (200, 503)  # 503: the page saying the front end is not built
        assert "scattertrack dashboard" in body


@pytest.mark.parametrize("via_env", [False, True], ids=["--token", "SCATTERTRACK_TOKEN"])
def test_with_a_token_every_request_carries_it(via_env, serve, get):
    token = "t0k-3n"
    args, env = ((), {"SCATTERTRACK_TOKEN": token}) if via_env else (("--token", token), {})
    with serve(*args, token=token, env=env) as url:
        for path in ("/api/health", "/", "/api/scenarios"):
            status, body = get(f"{url}{path}")
            assert status == 401, path
            assert "Bearer" in body
            assert get(f"{url}{path}", token="wrong")[0] == 401
            assert get(f"{url}{path}", token=token)[0] in (200, 503), path  # 503: front end not built
        assert get(f"{url}/api/health?token={token}")[0] == 200
        assert get(f"{url}/api/health?token=wrong")[0] == 401
