"""Regression tests for the API under bad or hostile input (issue 29): no 500s, bodies capped,
errors that never echo a large input, only loopback Host values, a capped run queue with
cancel and delete.
"""

import json
import subprocess
import sys
import textwrap

import pytest
from fastapi.testclient import TestClient

from nl2policy.app.guards import allowed_hosts_for
from nl2policy.app.server import create_app
from nl2policy.limits import MAX_BODY_BYTES, MAX_SEED

TREE = {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}


@pytest.fixture
def idle_client(tmp_path):
    """The real translator's entry checks, and a run manager that never starts a run
    (max_parallel_runs=0): runs stay queued, so the queue can be inspected without training."""
    app = create_app(tmp_path / "app.sqlite", tmp_path, translator=None, results_dir=tmp_path / "results",
                     max_parallel_runs=0, max_waiting_runs=3)
    with TestClient(app, base_url="http://127.0.0.1", raise_server_exceptions=False) as c:
        yield c


@pytest.mark.slow
def test_concurrent_first_translations_all_succeed(tmp_path):
    """On a fresh server, simultaneous first translate requests used to fail with 500 (a
    concurrent first import of transformers). A fresh interpreter, so nothing is loaded yet."""
    script = textwrap.dedent(f"""
        import json, threading
        from pathlib import Path
        from fastapi.testclient import TestClient
        from nl2policy.app.server import create_app
        base = Path({str(tmp_path)!r})
        app = create_app(base / "a.sqlite", base, results_dir=base)
        codes, start = [], threading.Barrier(8)
        with TestClient(app, base_url="http://127.0.0.1", raise_server_exceptions=False) as c:
            def post(i):
                start.wait()
                r = c.post("/api/translate", json={{"domain": "taxi" if i % 2 else "highway",
                                                   "description": "If I have a passenger I go to the airport."}})
                codes.append(r.status_code)
            threads = [threading.Thread(target=post, args=(i,)) for i in range(8)]
            [t.start() for t in threads]
            [t.join() for t in threads]
        print(json.dumps(codes))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == [200] * 8


@pytest.mark.parametrize("description", ["?!.,;", "...", " ?! "])
def test_description_without_words_is_422_not_500(idle_client, description):
    r = idle_client.post("/api/translate", json={"domain": "taxi", "description": description})
    assert r.status_code == 422
    assert "no words" in r.json()["detail"]["message"]


@pytest.mark.parametrize("seed", [2**63, 10**30, MAX_SEED + 1, -1])
def test_out_of_range_seeds_are_refused_at_the_boundary(idle_client, seed):
    r = idle_client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512, "seed": seed})
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "seed"]
    assert idle_client.get("/api/runs").json() == []  # nothing queued


def test_largest_seed_is_accepted(idle_client):
    r = idle_client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512, "seed": MAX_SEED})
    assert r.status_code == 201 and r.json()["seed"] == MAX_SEED


def test_fewer_steps_than_one_rollout_are_refused(idle_client):
    r = idle_client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 1})
    assert r.status_code == 422 and "at least 512" in r.json()["detail"]["message"]


def test_large_bodies_are_refused_and_errors_do_not_echo_them(idle_client):
    big = b'{"domain": "taxi", "description": "' + b"x" * (MAX_BODY_BYTES + 10) + b'"}'
    r = idle_client.post("/api/translate", content=big, headers={"Content-Type": "application/json"})
    assert r.status_code == 413 and len(r.content) < 500

    def chunks():  # no Content-Length: counted as it arrives
        for _ in range(30):
            yield b"x" * 100_000

    r = idle_client.post("/api/translate", content=chunks(), headers={"Content-Type": "application/json"})
    assert r.status_code == 413 and len(r.content) < 500
    r = idle_client.post("/api/translate", json={"domain": "taxi", "description": "y" * 200_000})
    assert r.status_code == 422 and len(r.content) < 1000
    assert "200,000 characters" in r.text  # says how long, does not repeat it


def test_small_chunked_bodies_still_work(idle_client):
    body = json.dumps({"domain": "taxi", "tree": TREE}).encode()
    r = idle_client.post("/api/validate", content=iter([body[:10], body[10:]]), headers={"Content-Type": "application/json"})
    assert r.status_code == 200 and r.json()["tree"] == TREE


def test_deeply_nested_tree_is_422(idle_client):
    deep = '{"do": "wait"}'
    for _ in range(3000):
        deep = f'{{"if": "at_city", "yes": {deep}, "no": {{"do": "wait"}}}}'
    r = idle_client.post("/api/validate", json={"domain": "taxi", "tree": deep})
    assert r.status_code == 422 and "nested too deeply" in r.json()["detail"]["message"]
    r = idle_client.post("/api/validate", content=f'{{"domain": "taxi", "tree": {deep}}}',
                         headers={"Content-Type": "application/json"})
    assert r.status_code in (400, 422)


@pytest.mark.parametrize("host,status", [
    ("127.0.0.1:8000", 200), ("localhost:8000", 200), ("[::1]:8000", 200), ("localhost", 200),
    ("attacker.example", 400), ("attacker.example:8000", 400), ("127.0.0.1.attacker.example", 400), ("", 400),
])
def test_only_loopback_host_headers_are_served(idle_client, host, status):
    assert idle_client.get("/api/domains", headers={"Host": host}).status_code == status


def test_allowed_hosts_follow_the_bind_address():
    assert "localhost" in allowed_hosts_for("127.0.0.1")
    assert "192.168.1.5" in allowed_hosts_for("192.168.1.5")
    assert allowed_hosts_for("0.0.0.0") is None  # published on purpose: any name
    assert set(allowed_hosts_for("0.0.0.0", ["box.lan"])) >= {"box.lan", "127.0.0.1"}


def test_run_queue_is_capped_and_runs_can_be_cancelled_and_deleted(idle_client, tmp_path):
    ids = [idle_client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512}).json()["id"] for _ in range(3)]
    r = idle_client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512})
    assert r.status_code == 429 and "waiting" in r.json()["detail"]
    assert idle_client.delete(f"/api/runs/{ids[0]}").status_code == 409  # queued: cancel first
    r = idle_client.post(f"/api/runs/{ids[0]}/cancel")
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    assert idle_client.post(f"/api/runs/{ids[0]}/cancel").status_code == 409
    (tmp_path / "runs" / ids[0]).mkdir(parents=True)
    assert idle_client.delete(f"/api/runs/{ids[0]}").json() == {"deleted": ids[0]}
    assert not (tmp_path / "runs" / ids[0]).exists()
    assert idle_client.get(f"/api/runs/{ids[0]}").status_code == 404
    assert idle_client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512}).status_code == 201
    assert idle_client.delete("/api/runs/nope").status_code == 404


def test_failed_runs_do_not_resume(idle_client):
    run_id = idle_client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512}).json()["id"]
    idle_client.app.state.store.set_run_status(run_id, "failed", error="boom")
    r = idle_client.post(f"/api/runs/{run_id}/resume")
    assert r.status_code == 409 and "boom" in r.json()["detail"]


@pytest.mark.parametrize("host,extra,warned,allowed", [
    ("127.0.0.1", [], False, {"127.0.0.1", "localhost", "::1"}),
    ("0.0.0.0", [], True, None),
    ("0.0.0.0", ["--allow-host", "box.lan"], True, {"127.0.0.1", "localhost", "::1", "box.lan"}),
    ("192.168.1.5", [], True, {"127.0.0.1", "localhost", "::1", "192.168.1.5"}),
])
def test_serve_warns_beyond_loopback_and_passes_the_allowed_hosts(tmp_path, monkeypatch, host, extra, warned, allowed):
    import uvicorn
    from typer.testing import CliRunner

    import nl2policy.app.server as server
    from nl2policy.cli import app

    seen = {}
    real_create_app = server.create_app
    monkeypatch.setattr(server, "create_app", lambda *a, **kw: seen.update(kw) or real_create_app(*a, **kw))
    monkeypatch.setattr(uvicorn, "run", lambda application, **kw: seen.update(run=kw))
    monkeypatch.setattr("nl2policy.app.commands._port_free_or_fail", lambda host, port: None)  # 192.168.1.5 is not ours
    result = CliRunner().invoke(app, ["serve", "--host", host, "--data-dir", str(tmp_path), *extra])
    assert result.exit_code == 0, result.output
    assert ("warning: listening on" in result.stderr) == warned
    assert seen["run"]["host"] == host
    assert (None if seen["allowed_hosts"] is None else set(seen["allowed_hosts"])) == allowed


@pytest.mark.parametrize("method,path,body", [
    ("post", "/api/translate", {"domain": "d" * 500_000, "description": "go"}),
    ("post", "/api/validate", {"domain": "taxi", "tree": {"do": "y" * 500_000}}),
    ("post", "/api/validate", {"domain": "taxi", "tree": {"if": "q" * 500_000, "yes": {"do": "wait"}, "no": {"do": "wait"}}}),
    ("post", "/api/runs", {"domain": "taxi", "tree": {"do": "wait"}, "spec_id": "s" * 300_000, "steps": "n" * 300_000}),
])
def test_errors_never_echo_a_large_input(idle_client, method, path, body):
    r = getattr(idle_client, method)(path, json=body)
    assert r.status_code in (404, 422) and len(r.content) < 2000, r.text[:200]
