"""What the pages show, computed by the API (issue 29): progress in steps that never passes the
total, a readable result with a reason when the tree did not change, places in words, edited
nodes without the translator's confidence, the API reference and favicon served offline."""

import json
import re

import pytest
from fastapi.testclient import TestClient

from nl2policy.app import outcome
from nl2policy.app.places import place
from nl2policy.app.server import create_app
from nl2policy.domains import get_domain
from test_app_api import fake_translator

RUN = {"domain": "taxi", "steps": 3000, "status": "running", "summary": None}


def test_progress_never_passes_the_total_and_estimates_the_time_left(tmp_path):
    (tmp_path / "state.json").write_text(json.dumps({"steps": 1536, "seconds": 6.0}))
    p = outcome.progress({**RUN, "out_dir": str(tmp_path)})
    assert p == {"done": 1536, "total": 3072, "seconds": 6.0, "eta_seconds": 6.0}  # 3,000 asked: 6 rollouts of 512
    (tmp_path / "state.json").write_text(json.dumps({"steps": 3584, "seconds": 9.0}))
    assert outcome.progress({**RUN, "out_dir": str(tmp_path)})["done"] == 3072
    (tmp_path / "state.json").write_text("{half written")
    assert outcome.progress({**RUN, "out_dir": str(tmp_path)})["done"] == 0
    done = outcome.progress({**RUN, "status": "finished", "out_dir": str(tmp_path), "summary": {"seconds": 12.34}})
    assert done == {"done": 3072, "total": 3072, "seconds": 12.3, "eta_seconds": None}


SUMMARY = {"steps": 2048, "seconds": 10.0, "eval_episodes": 200, "initial_mean_return": 5.0, "final_mean_return": 5.0,
           "final_tree_has_raw_tests": False}


@pytest.mark.parametrize("summary,changed,words", [
    ({**SUMMARY, "final_mean_return": 7.5}, [1, 2], "found a better tree"),
    ({**SUMMARY, "final_mean_return": 4.0}, [1], "does no better than yours"),
    (SUMMARY, [], "did not change: in 2,048 steps training found no better tree"),
    ({**SUMMARY, "exact_initial_tree": 5.0, "exact_final_tree": 5.0, "exact_best_tree": 6.0, "best_tree_step": 1024}, [],
     "at step 1024 training passed a better one"),
    ({**SUMMARY, "final_tree_has_raw_tests": True, "final_mean_return": 7.5}, [1],
     "found a better tree: 1 node(s) changed (in yellow). Training also moved a question's threshold"),
])
def test_result_is_readable_and_says_why(summary, changed, words):
    r = outcome.result(summary, changed)
    assert words in r["verdict"]
    assert r["change"] == round(r["after"] - r["before"], 2) and r["seconds"] == 10.0


def test_exact_returns_are_preferred_when_the_run_has_them():
    r = outcome.result({**SUMMARY, "exact_initial_tree": 6.2057, "exact_final_tree": 7.9399}, [3])
    assert (r["before"], r["after"], r["change"]) == (6.21, 7.94, 1.73) and "exact" in r["measure"]


def test_places_in_words(taxi):
    grid = ["has_passenger", "go_airport", "heavy_traffic"] + [None] * 12
    assert place("slot 0", taxi.vocab, grid=grid) == "the first question"
    assert place("slot 2", taxi.vocab, grid=grid) == 'the "no" answer to "Does the taxi have a passenger?"'
    tree = {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"if": "heavy_traffic", "yes": {}, "no": {}}}
    assert place("root.no.yes", taxi.vocab, tree=tree) == f'the "yes" answer to "{taxi.vocab.questions["heavy_traffic"]}"'
    assert place("token 4", taxi.vocab) == "token 4"


@pytest.fixture
def client(tmp_path):
    app = create_app(tmp_path / "app.sqlite", tmp_path, translator=fake_translator, results_dir=tmp_path / "results",
                     max_parallel_runs=0)
    with TestClient(app, base_url="http://127.0.0.1") as c:
        yield c


def test_tree_errors_name_the_place_in_words(client):
    grid = ["has_passenger", "go_airport", None] + [None] * 12
    detail = client.post("/api/validate", json={"domain": "taxi", "grid": grid}).json()["detail"]
    assert detail["where"] == "slot 2"
    assert detail["error"].startswith('the "no" answer to "Does the taxi have a passenger?"')


def test_an_edited_node_loses_the_translators_confidence(client):
    spec = client.post("/api/translate", json={"domain": "taxi", "description": "x"}).json()
    assert set(spec["node_confidence"]) >= {"0", "1", "2"}
    grid = list(spec["grid"])
    replaced = next(i for i, item in enumerate(grid) if i > 0 and item and item not in get_domain("taxi").vocab.questions)
    grid[replaced] = next(a for a in get_domain("taxi").vocab.actions if a != grid[replaced]
                          and a != grid[replaced + (1 if replaced % 2 else -1)])
    edited = client.put(f"/api/specs/{spec['spec_id']}", json={"domain": "taxi", "grid": grid}).json()
    assert str(replaced) not in edited["node_confidence"]
    assert set(edited["node_confidence"]) == set(spec["node_confidence"]) - {str(replaced)}


def test_runs_report_progress_in_the_list_and_the_view(client):
    run = client.post("/api/runs", json={"domain": "taxi", "tree": {"do": "wait"}, "steps": 1000}).json()
    assert run["progress"] == {"done": 0, "total": 1024, "seconds": None, "eta_seconds": None}
    assert client.get("/api/runs").json()[0]["progress"]["total"] == 1024


def test_api_reference_and_favicon_are_served_offline(client):
    page = client.get("/docs")
    assert page.status_code == 200 and "/openapi.json" in page.text
    assert not re.findall(r'(?:src|href)="(?:https?:)?//', page.text)  # nothing fetched from elsewhere
    icon = client.get("/favicon.ico")
    assert icon.status_code == 200 and icon.headers["content-type"].startswith("image/svg+xml")
    for path in ("/", "/optimize", "/collect"):
        assert 'rel="icon"' in client.get(path).text and 'name="viewport"' in client.get(path).text
