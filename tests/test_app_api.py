"""The app's JSON API: specify, edit, validate, collect/export, runs, and bad input.

The translator here is a small test double that returns a corpus tree with made-up node
confidences, so these tests pin the server's behaviour alone; the real translator is
exercised in the translation tests and in the browser test.
"""

import json
import threading
from dataclasses import dataclass, field

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from nl2policy.app.server import create_app
from nl2policy.language.corpus import load_corpus
from nl2policy.trees import to_grid


@dataclass
class FakeTranslation:
    tree: object
    confidence: float
    warnings: list = field(default_factory=list)
    node_confidence: dict = field(default_factory=dict)


def fake_translator(domain, text):
    tree = load_corpus(domain)[4].tree
    grid = to_grid(tree)
    return FakeTranslation(tree, 0.42, ["low confidence"], {i: (0.3 if i == 2 else 0.9) for i, s in enumerate(grid) if s})


@pytest.fixture
def client(tmp_path):
    app = create_app(tmp_path / "app.sqlite", tmp_path, translator=fake_translator, results_dir=tmp_path / "results")
    with TestClient(app, base_url="http://127.0.0.1") as c:
        yield c


def test_openapi_schema_lists_every_action(client):
    paths = client.get("/openapi.json").json()["paths"]
    for p in ["/api/translate", "/api/validate", "/api/specs/{spec_id}", "/api/runs", "/api/runs/{run_id}",
              "/api/runs/{run_id}/resume", "/api/runs/{run_id}/policy", "/api/submissions", "/api/domains"]:
        assert p in paths


def test_pages_are_served(client):
    for page in ("/", "/optimize", "/collect"):
        r = client.get(page)
        assert r.status_code == 200 and "<html" in r.text


def test_translate_stores_a_spec_with_confidences(client):
    r = client.post("/api/translate", json={"domain": "taxi", "description": "passenger: airport; else city unless jammed"})
    assert r.status_code == 200
    body = r.json()
    assert body["confidence"] == 0.42 and body["warnings"] == ["low confidence"]
    assert body["svg"].startswith("<svg") and "#ffcdd2" in body["svg"]  # the unsure node is marked
    assert "confidence 30%" in body["svg"]
    spec = client.get(f"/api/specs/{body['spec_id']}").json()
    assert spec["tree"] == body["tree"] and spec["description"].startswith("passenger")


def test_edit_is_validated_and_bad_edits_change_nothing(client):
    spec = client.post("/api/translate", json={"domain": "taxi", "description": "x"}).json()
    grid = list(spec["grid"])
    grid[1] = "go_village"
    r = client.put(f"/api/specs/{spec['spec_id']}", json={"domain": "taxi", "grid": grid})
    assert r.status_code == 200 and r.json()["tree"]["yes"] == {"do": "go_village"}
    bad = list(grid)
    bad[1] = "has_passenger"  # repeats the root question on the path and has no answers
    r = client.put(f"/api/specs/{spec['spec_id']}", json={"domain": "taxi", "grid": bad})
    assert r.status_code == 422 and "slot" in r.json()["detail"]["where"]
    assert client.get(f"/api/specs/{spec['spec_id']}").json()["tree"]["yes"] == {"do": "go_village"}
    r = client.put(f"/api/specs/{spec['spec_id']}", json={"domain": "taxi", "tree": {"do": "fly"}})
    assert r.status_code == 422 and "unknown action 'fly'" in r.json()["detail"]["message"]


@pytest.mark.parametrize("payload,status", [
    ({"domain": "taxi", "description": ""}, 422),
    ({"domain": "taxi", "description": "   "}, 422),
    ({"domain": "taxi", "description": "x" * 6000}, 422),
    ({"domain": "boat", "description": "drive"}, 404),
    ({"description": "drive"}, 422),
])
def test_bad_translate_requests(client, payload, status):
    assert client.post("/api/translate", json=payload).status_code == status


def test_malformed_json_body_is_rejected(client):
    r = client.post("/api/translate", content=b'{"domain": "taxi", "descr', headers={"Content-Type": "application/json"})
    assert r.status_code == 422
    r = client.post("/api/validate", json={"domain": "taxi", "tree": '{"if": "at_city"'})
    assert r.status_code == 422 and "malformed JSON" in r.json()["detail"]["message"]


def test_unknown_ids_are_404(client):
    assert client.get("/api/specs/nope").status_code == 404
    assert client.get("/api/runs/nope").status_code == 404
    assert client.post("/api/runs/nope/resume").status_code == 404


def test_collect_submit_and_export(client, tmp_path):
    grid = [None] * 15
    grid[0], grid[1], grid[2] = "has_passenger", "go_airport", "go_city"
    r = client.post("/api/submissions", json={"domain": "taxi", "writer": "ana", "grid": grid,
                                              "description": "With a fare go to the airport, else the city."})
    assert r.status_code == 201
    bad = list(grid)
    bad[2] = None
    r = client.post("/api/submissions", json={"domain": "taxi", "writer": "ana", "grid": bad, "description": "d"})
    assert r.status_code == 422 and r.json()["detail"]["where"] == "slot 2"
    r = client.post("/api/submissions", json={"domain": "taxi", "writer": "ana", "grid": grid, "description": ""})
    assert r.status_code == 422
    assert len(client.get("/api/submissions?domain=taxi").json()) == 1

    from nl2policy.cli import app

    out = tmp_path / "export.jsonl"
    res = CliRunner().invoke(app, ["export-submissions", "--domain", "taxi", "--out", str(out), "--db", str(tmp_path / "app.sqlite")])
    assert res.exit_code == 0, res.output
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(rows) == 1
    assert set(rows[0]) == {"id", "domain", "writer", "tree", "description"}
    assert rows[0]["tree"] == {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}
    from nl2policy.domains import get_domain
    from nl2policy.trees import parse_tree

    parse_tree(rows[0]["tree"], get_domain("taxi").vocab)


def test_concurrent_submissions_all_land(client):
    grid = [None] * 15
    grid[0], grid[1], grid[2] = "has_passenger", "go_airport", "go_city"
    codes = []

    def post(i):
        codes.append(client.post("/api/submissions", json={"domain": "taxi", "writer": f"w{i}", "grid": grid,
                                                           "description": f"spec {i}"}).status_code)

    threads = [threading.Thread(target=post, args=(i,)) for i in range(12)]
    [t.start() for t in threads]
    [t.join() for t in threads]
    assert codes == [201] * 12
    assert sorted(r["description"] for r in client.get("/api/submissions").json()) == sorted(f"spec {i}" for i in range(12))


def test_run_rejects_bad_trees_and_budgets(client):
    assert client.post("/api/runs", json={"domain": "taxi", "tree": {"do": "fly"}}).status_code == 422
    assert client.post("/api/runs", json={"domain": "taxi", "tree": {"do": "wait"}, "steps": 10**9}).status_code == 422
    assert client.post("/api/runs", json={"domain": "boat", "tree": {"do": "wait"}}).status_code == 404


def test_baseline_curves_are_medians_over_seeds(tmp_path):
    runs = tmp_path / "results" / "policy" / "taxi" / "runs"
    for seed, level in enumerate((1.0, 2.0, 4.0)):
        d = runs / f"mlp_s{seed}"
        d.mkdir(parents=True)
        rows = ["episode,step,return,rolling_mean_100"] + [f"{i},{i * 100},{level},{level * i / 10:.4f}" for i in range(1, 11)]
        (d / "curve.csv").write_text("\n".join(rows) + "\n")
    app = create_app(tmp_path / "a.sqlite", tmp_path, translator=fake_translator, results_dir=tmp_path / "results")
    with TestClient(app, base_url="http://127.0.0.1") as c:
        body = c.get("/api/baselines/taxi").json()
        assert set(body["curves"]) == {"MLP"}
        last_step, last_value = body["curves"]["MLP"][-1]
        assert last_step == 1000 and abs(last_value - 2.0) < 1e-6  # median of 1, 2, 4
        assert c.get("/api/baselines/boat").status_code == 404
