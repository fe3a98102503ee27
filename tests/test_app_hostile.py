"""The app and the CLI under what a hostile page, a broken database or a careless shell sends
(issue 44): cross-site requests change nothing, every response carries the security headers,
text that is not Unicode or shows nothing is refused without being echoed, slow bodies time
out, the run manager outlives a locked or damaged database, and the CLI ends every expected
error in one line."""

import json
import os
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import uvicorn
from fastapi.testclient import TestClient

from nl2policy.app.server import create_app

TREE = {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}
HEADERS = {"x-content-type-options": "nosniff", "x-frame-options": "DENY",
           "content-security-policy": "frame-ancestors 'none'"}
EVIL = {"Origin": "http://evil.example", "Content-Type": "text/plain"}


@pytest.fixture
def idle(tmp_path):
    """A server whose run manager never starts a run, so queued runs stay queued."""
    app = create_app(tmp_path / "app.sqlite", tmp_path, translator=lambda d, t: _fake_translation(d),
                     results_dir=tmp_path, max_parallel_runs=0)
    with TestClient(app, base_url="http://127.0.0.1", raise_server_exceptions=False) as c:
        yield c


def _fake_translation(domain):
    from nl2policy.domains import get_domain
    from nl2policy.language.translate import Translation
    from nl2policy.trees import parse_tree

    return Translation(parse_tree(TREE, get_domain(domain).vocab), 0.9)


def _queued(client) -> dict:
    r = client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512})
    assert r.status_code == 201
    return r.json()


@pytest.mark.parametrize("headers", [EVIL, {"Origin": "null", "Content-Type": "text/plain"},
                                     {"Sec-Fetch-Site": "cross-site", "Content-Type": "text/plain"},
                                     {"Origin": "http://127.0.0.1:9999", "Content-Type": "text/plain"}])
def test_cross_site_requests_are_refused_and_change_nothing(idle, headers):
    run = _queued(idle)
    idle.post(f"/api/runs/{run['id']}/cancel")  # cancelled: so resume and delete would act
    before = idle.get("/api/runs").json()
    for method, url, body in [("POST", f"/api/runs/{run['id']}/resume", None), ("DELETE", f"/api/runs/{run['id']}", None),
                              ("POST", "/api/runs", json.dumps({"domain": "taxi", "tree": TREE, "steps": 512})),
                              ("POST", f"/api/runs/{run['id']}/cancel", None),
                              ("POST", "/api/translate", json.dumps({"domain": "taxi", "description": "go to the city"}))]:
        r = idle.request(method, url, content=body, headers=headers)
        assert r.status_code == 403, (method, url, r.text)
        assert "refused" in r.json()["detail"]["message"]
    after = idle.get("/api/runs").json()
    assert [(r["id"], r["status"]) for r in after] == [(r["id"], r["status"]) for r in before]
    assert idle.get(f"/api/specs/none").status_code == 404


def test_same_origin_requests_still_work(idle):
    run = _queued(idle)
    r = idle.post(f"/api/runs/{run['id']}/cancel", headers={"Origin": "http://127.0.0.1", "Sec-Fetch-Site": "same-origin"})
    assert r.status_code == 200 and r.json()["status"] == "cancelled"


def test_a_body_that_is_not_json_is_refused(idle):
    r = idle.post("/api/runs", content=json.dumps({"domain": "taxi", "tree": TREE}), headers={"Content-Type": "text/plain"})
    assert r.status_code == 415 and "application/json" in r.json()["detail"]["message"]
    assert idle.get("/api/runs").json() == []


@pytest.mark.parametrize("path", ["/", "/optimize", "/api/domains", "/api/runs/nope", "/static/common.js", "/docs"])
def test_every_response_carries_the_security_headers(idle, path):
    r = idle.get(path)
    for name, value in HEADERS.items():
        assert r.headers.get(name) == value, (path, name)


def test_refusals_carry_the_security_headers_too(idle):
    for r in (idle.get("/", headers={"Host": "evil.example"}), idle.post("/api/runs", content="x", headers=EVIL)):
        assert r.status_code in (400, 403)
        assert all(r.headers.get(k) == v for k, v in HEADERS.items())


@pytest.mark.parametrize("url,body", [
    ("/api/translate", b'{"domain": "taxi", "description": "go to the \\ud800 city"}'),
    ("/api/runs", b'{"domain": "taxi", "tree": {"do": "wait"}, "steps": "\\ud800"}'),
    ("/api/submissions", b'{"domain": "taxi", "writer": "\\udfff", "grid": ["wait"], "description": "wait"}'),
    ("/api/validate", b'{"domain": "taxi", "tree": {"do": "\\ud800"}}'),
    ("/api/translate", b'{"domain": "\\ud83d", "description": "x"}'),
])
def test_lone_surrogates_are_refused_without_being_echoed(idle, url, body):
    r = idle.post(url, content=body, headers={"Content-Type": "application/json"})
    assert r.status_code == 422, r.text
    assert "not valid Unicode" in r.json()["detail"]["message"]
    assert "\\ud8" not in r.text.lower().replace("\\\\ud800", "")  # the message names the kind, never the input
    assert idle.get("/api/runs").json() == [] and idle.get("/api/submissions").json() == []


def test_invalid_utf8_bytes_are_a_clear_4xx(idle):
    r = idle.post("/api/translate", content=b'{"domain": "taxi", "description": "\xff\xfe"}',
                  headers={"Content-Type": "application/json"})
    assert r.status_code in (400, 422) and r.json()["detail"]


@pytest.mark.parametrize("text", ["\u200b\u200b", "\u200d \ufeff", "\u2060\n\t", "\u00a0"])
def test_a_description_of_invisible_characters_is_empty(idle, text):
    r = idle.post("/api/translate", json={"domain": "taxi", "description": text})
    assert r.status_code == 422 and "empty" in r.json()["detail"]["message"]


@pytest.mark.parametrize("writer", ["   ", "\u200b", "\t\n"])
def test_a_writer_name_that_shows_nothing_is_refused(idle, writer):
    r = idle.post("/api/submissions", json={"domain": "taxi", "writer": writer, "grid": ["wait"] + [None] * 14,
                                            "description": "always wait"})
    assert r.status_code == 422 and r.json()["detail"]["where"] == "writer"
    assert idle.get("/api/submissions").json() == []


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def live(tmp_path):
    """The app on a real socket (uvicorn in a thread), with a 2-second body deadline."""
    app = create_app(tmp_path / "app.sqlite", tmp_path, translator=lambda d, t: _fake_translation(d),
                     results_dir=tmp_path, body_timeout=2.0)
    port = free_port()
    srv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.time() + 30
    while not srv.started and time.time() < deadline:
        time.sleep(0.05)
    yield port, tmp_path
    srv.should_exit = True
    thread.join(timeout=15)


@pytest.mark.slow
def test_a_half_sent_body_gets_408_and_the_connection_ends(live):
    port, _ = live
    with socket.create_connection(("127.0.0.1", port), timeout=15) as s:
        s.sendall(b"POST /api/translate HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                  b"Content-Length: 100\r\n\r\n{\"domain\":")
        start = time.time()
        reply = b""
        while True:
            chunk = s.recv(4096)
            if not chunk:
                break
            reply += chunk
        took = time.time() - start
    assert reply.startswith(b"HTTP/1.1 408"), reply[:200]
    assert took < 10


@pytest.mark.slow
def test_a_queued_run_starts_after_a_lock_longer_than_the_busy_timeout_and_after_a_damaged_file(live, monkeypatch):
    """The run manager used to die on the first store error, leaving every later run queued."""
    port, base = live
    import httpx

    from nl2policy.app import store

    monkeypatch.setattr(store, "BUSY_TIMEOUT_S", 3.0)  # SQLite's wait, 30 s in the product

    url = f"http://127.0.0.1:{port}"
    db = base / "app.sqlite"
    with httpx.Client(base_url=url, timeout=60) as client:
        def start_and_wait() -> float:
            run = client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512}).json()
            t0 = time.time()
            while time.time() - t0 < 30:
                if client.get(f"/api/runs/{run['id']}").json()["status"] != "queued":
                    return time.time() - t0
                time.sleep(0.2)
            raise AssertionError("the queued run did not start within 30 s")

        # another process holds an exclusive lock for 5 s: longer than the store's busy timeout
        locker = subprocess.Popen([sys.executable, "-c", f"""
import sqlite3, time
db = sqlite3.connect({str(db)!r}, isolation_level=None)
db.execute("BEGIN EXCLUSIVE"); print("locked", flush=True); time.sleep(5); db.execute("COMMIT")
"""], stdout=subprocess.PIPE, text=True)
        assert locker.stdout.readline().strip() == "locked"
        locker.wait(timeout=60)
        assert start_and_wait() < 30
        # the file damaged under the running server, then restored
        with sqlite3.connect(db) as conn:
            conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        good = db.read_bytes()
        db.write_bytes(b"\0" * 100 + os.urandom(len(good) - 100))
        time.sleep(4)  # the manager polls the store every second: it meets the damage
        assert client.get("/api/runs").status_code == 503
        db.write_bytes(good)
        assert start_and_wait() < 30


def _cli(*args: bytes, env: dict | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    code = "import sys; from nl2policy.cli import main; sys.exit(main())"
    return subprocess.run([sys.executable.encode(), b"-c", code.encode(), *args], capture_output=True, timeout=timeout,
                          env={**os.environ, **(env or {})})


def _one_line(proc: subprocess.CompletedProcess, needle: str) -> None:
    err = proc.stderr.decode(errors="replace")
    assert proc.returncode == 2, (proc.returncode, err[-1500:])
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], err


def test_cli_invalid_utf8_in_argv():
    _one_line(_cli(b"translate", b"--domain", b"taxi", b"go to the \xff city"), "not valid Unicode")


def test_cli_train_translator_into_an_unwritable_folder(tmp_path):
    target = tmp_path / "ro"
    target.mkdir()
    target.chmod(0o500)
    try:
        where = b"/proc/nl2policy-out" if os.geteuid() == 0 else str(target / "models").encode()
        _one_line(_cli(b"train-translator", b"--domain", b"taxi", b"--out", where), "cannot write")
    finally:
        target.chmod(0o700)


def test_cli_corpus_folder_missing(tmp_path):
    """Training reads the corpus and says which folder lacks it; translating needs only the
    domain's folder, so it still works."""
    env = {"NL2POLICY_CORPUS": str(tmp_path / "none")}
    _one_line(_cli(b"train-translator", b"--domain", b"taxi", b"--out", str(tmp_path / "m").encode(), env=env), "NL2POLICY_CORPUS")
    assert _cli(b"translate", b"--domain", b"taxi", b"go to the city", env=env).returncode == 0


@pytest.mark.parametrize("args", [[b"optimize", b"--domain", b"taxi", b"--tree", b'{"do": "wait"}', b"--steps", b"100000000000000000000"],
                                  [b"evaluate", b"--domain", b"taxi", b"--tree", b'{"do": "wait"}', b"--episodes", b"10000000000"],
                                  [b"compare", b"--episodes", b"0"], [b"no-such-command"]])
def test_cli_impossible_numbers_and_usage_errors_are_one_line(args):
    _one_line(_cli(*args, timeout=60), "error:")
