"""Optimization runs through the app: background, queued one at a time, survive a restart."""

import time

import pytest
from fastapi.testclient import TestClient

from nl2policy.app.server import create_app

pytestmark = pytest.mark.train

TREE = {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}


def wait_for(client, run_id, states, timeout=180):
    deadline = time.time() + timeout
    while time.time() < deadline:
        view = client.get(f"/api/runs/{run_id}").json()
        if view["status"] in states:
            return view
        time.sleep(0.5)
    raise AssertionError(f"run {run_id} still {view['status']} after {timeout}s: {view.get('error')}")


def make_client(tmp_path):
    return TestClient(create_app(tmp_path / "app.sqlite", tmp_path, translator=None, results_dir=tmp_path / "results"),
                      base_url="http://127.0.0.1")


def test_run_finishes_with_curve_final_tree_and_download(tmp_path):
    with make_client(tmp_path) as client:
        r = client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 1024, "seed": 1})
        assert r.status_code == 201
        second = client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512, "seed": 2}).json()
        assert second["status"] == "queued"  # one run at a time on a 2-core machine
        view = wait_for(client, r.json()["id"], {"finished", "failed"})
        assert view["status"] == "finished", view["error"]
        assert view["curve"] and view["curve"][-1]["step"] <= 1024
        assert view["final"]["tree"] and isinstance(view["final"]["changed"], list)
        assert view["summary"]["steps"] >= 1024
        policy = client.get(f"/api/runs/{view['id']}/policy")
        assert policy.status_code == 200 and "attachment" in policy.headers["content-disposition"]
        assert policy.json()["initial_tree"] == TREE
        assert wait_for(client, second["id"], {"finished", "failed"})["status"] == "finished"
        assert client.post(f"/api/runs/{view['id']}/resume").status_code == 409


def test_restart_keeps_finished_runs_and_resumes_interrupted_ones(tmp_path):
    with make_client(tmp_path) as client:
        done = client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512}).json()
        wait_for(client, done["id"], {"finished"})
        long = client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 4_096}).json()
        wait_for(client, long["id"], {"running"})
        deadline = time.time() + 120
        while not client.get(f"/api/runs/{long['id']}").json()["curve"] and time.time() < deadline:
            time.sleep(0.5)  # wait for the first checkpoint
    # the server stopped mid-run
    with make_client(tmp_path) as client:
        assert client.get(f"/api/runs/{done['id']}").json()["status"] == "finished"
        view = client.get(f"/api/runs/{long['id']}").json()
        assert view["status"] == "interrupted"
        steps_before = view["curve"][-1]["step"]
        assert 0 < steps_before < 4_096
        assert client.post(f"/api/runs/{long['id']}/resume").json()["status"] in ("queued", "running")
        view = wait_for(client, long["id"], {"finished", "failed"}, timeout=300)
        assert view["status"] == "finished", view["error"]
        assert view["summary"]["steps"] >= 4_096
