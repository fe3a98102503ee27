"""End to end in a real browser (Playwright driving Debian's chromium, headless): describe,
see the tree, edit a node, optimize briefly, see the curve, the readable result and the final
tree; the Optimize page's live run list and cancel; the Specify page's domain switch, edit menu
and back/forward; build and submit a tree on the Collect page and find it in the export; the
pages on a phone-sized screen and the offline API reference.

Set NL2POLICY_SCREENSHOTS=docs to save a screenshot of each page there (``make screenshots``).
"""

import json
import os
import shutil
import socket
import threading
import time
from pathlib import Path

import pytest
import uvicorn
from typer.testing import CliRunner

from nl2policy.app.server import create_app

pytestmark = pytest.mark.browser

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
        "--disable-component-update", "--disable-sync"]
DESCRIPTION = ("If I have a passenger, I drive to the airport. If not, I look at the road to the city: "
               "when the traffic is heavy I go to the village, otherwise I go to the city.")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    if not Path(CHROMIUM).exists():
        pytest.fail("chromium is not installed: run `make setup` (it installs Debian's chromium)")
    base = tmp_path_factory.mktemp("app")
    app = create_app(base / "app.sqlite", base, results_dir=Path(__file__).resolve().parents[1] / "results")
    port = free_port()
    srv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.time() + 30
    while not srv.started and time.time() < deadline:
        time.sleep(0.1)
    # The first translation in a process loads the translator and builds MiniLM's saved forward:
    # seconds alone, a minute or more beside a busy test worker. Done here, in the server's
    # process, so each page's waits time the page and not that one-off load.
    from nl2policy.language.translate import translate

    for domain in ("taxi", "highway"):
        translate(domain, DESCRIPTION)
    yield f"http://127.0.0.1:{port}", base
    srv.should_exit = True
    thread.join(timeout=15)


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        yield b
        b.close()


def shoot(page, name: str) -> None:
    folder = os.environ.get("NL2POLICY_SCREENSHOTS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(Path(folder) / f"{name}.png"), full_page=True)


def test_specify_edit_optimize(server, browser):
    url, _ = server
    page = browser.new_page(viewport={"width": 1100, "height": 900})
    page.goto(url + "/")
    page.select_option("#domain", "taxi")
    page.fill("#description", DESCRIPTION)
    page.click("#translate")
    page.wait_for_selector("#tree svg g[data-slot='0']", timeout=120_000)
    assert "confidence" in page.inner_text("#confidence")
    assert page.locator("#tree g[data-slot]").count() >= 3
    shoot(page, "specify")

    # edit: the answer of the root's "yes" branch becomes "Wait here for a passenger"
    page.click("#tree g[data-slot='1']")
    page.select_option("#edit-choice", "wait")
    page.click("#apply-edit")
    page.wait_for_function("document.querySelector('#tree g[data-slot=\"1\"]').dataset.id === 'wait'")
    assert page.inner_text("#edit-error") == ""

    page.fill("#steps", "1024")
    page.click("#optimize")
    page.wait_for_url("**/optimize?run=*")
    page.set_viewport_size({"width": 1280, "height": 900})
    page.wait_for_function("document.querySelector('#status').textContent === 'finished'", timeout=240_000)
    page.wait_for_selector("#curve polyline[data-name='run']")
    page.wait_for_selector("#final svg")
    assert page.locator("#initial svg").count() == 1
    assert page.locator("#download").is_visible()
    # a readable result, not a JSON dump: returns before/after, the change, the time, a verdict
    assert page.locator("#result").is_visible() and not page.locator("#summary").is_visible()
    for cell in ("#before", "#after", "#change"):
        float(page.inner_text(cell).replace("+", ""))
    assert "steps" in page.inner_text("#took") and page.inner_text("#verdict").strip()
    assert page.inner_text("#progress").endswith("1,024 of 1,024 steps")
    # the legend sits below the plot, outside the SVG, so it cannot cover a curve
    assert page.locator("#curve svg text", has_text="this run").count() == 0
    assert page.locator("#legend span", has_text="this run").count() == 1
    shoot(page, "optimize")
    page.close()


def _act(tree: dict, situation: dict) -> str:
    while "do" not in tree:
        tree = tree["yes"] if situation[tree["if"]] else tree["no"]
    return tree["do"]


def test_specify_asks_about_situations_and_each_answer_changes_the_tree(server, browser):
    """Describe vaguely; the page asks what to do in a situation; answering with an action the
    tree does not take there redraws the tree with the changed boxes marked, twice; then the
    tree is optimized."""
    url, _ = server
    page = browser.new_page(viewport={"width": 1100, "height": 900})
    page.goto(url + "/")
    page.select_option("#domain", "taxi")
    page.fill("#description", "Drive around and make money, but mind the traffic.")
    page.click("#translate")
    page.wait_for_selector("#tree svg g[data-slot='0']", timeout=120_000)
    for turn in range(2):
        page.wait_for_selector("#question-choices button[data-do]", timeout=60_000)
        assert "What should it do?" in page.inner_text("#question-text")
        tree, situation = page.evaluate("[spec.tree, asked.situation]")
        other = next(a for a in ("go_airport", "go_village", "go_city", "wait") if a != _act(tree, situation))
        page.click(f"#question-choices button[data-do='{other}']")
        page.wait_for_function("document.querySelector('#question-note').textContent !== ''", timeout=60_000)
        new_tree = page.evaluate("spec.tree")
        assert new_tree != tree and _act(new_tree, situation) == other
        assert page.locator("#tree g.changed").count() >= 1
        assert "changed" in page.inner_text("#question-note")
    if page.locator("#skip-question").count():
        page.click("#skip-question")
        assert page.locator("#questions").is_hidden()
    shoot(page, "specify-questions")
    page.fill("#steps", "512")
    page.click("#optimize")
    page.wait_for_url("**/optimize?run=*")
    page.wait_for_function("['running', 'finished'].includes(document.querySelector('#status').textContent)", timeout=120_000)
    page.close()


def test_collect_build_submit_and_export(server, browser):
    url, base = server
    page = browser.new_page(viewport={"width": 1100, "height": 1700})  # the drag's source and target both in view
    page.goto(url + "/collect")
    page.wait_for_selector("#palette span")
    page.select_option("#domain", "taxi")
    page.wait_for_selector("#palette span[data-id='has_passenger']")
    # the briefing is formatted text, and the grid says which box answers yes and which no
    assert page.locator("#briefing b", has_text="airport").count() >= 1 and page.locator("#briefing li").count() >= 6
    assert "**" not in page.inner_text("#briefing")
    assert page.inner_text(".slot[data-slot='1'] .answer-tag").lower() == "if yes"
    assert page.inner_text(".slot[data-slot='2'] .answer-tag").lower() == "if no"
    page.fill("#writer", "browser-test")
    page.click(".slot[data-slot='0']")
    page.click("#palette span[data-id='has_passenger']")
    page.drag_and_drop("#palette span[data-id='go_airport']", ".slot[data-slot='1']")
    page.click(".slot[data-slot='2']")
    page.click("#palette span[data-id='go_city']")
    # submitting without a description is refused
    page.click("#submit")
    page.wait_for_function("document.querySelector('#error').textContent.length > 0")
    page.fill("#description", "With a passenger head for the airport; without one, go to the city.")
    # back and forward (or a reload) keep the tree being built
    page.goto(url + "/")
    page.go_back()
    page.wait_for_selector(".slot[data-slot='2'].action")
    assert page.inner_text(".slot[data-slot='1'] .slot-text") == "Drive to the airport"
    assert page.input_value("#description").startswith("With a passenger")
    shoot(page, "collect")
    page.click("#submit")
    page.wait_for_function("document.querySelector('#ok').textContent.startsWith('Thank you') || "
                           "document.querySelector('#error').textContent.length > 0")
    assert page.inner_text("#error") == ""
    page.close()

    from nl2policy.cli import app

    out = base / "export.jsonl"
    res = CliRunner().invoke(app, ["export-submissions", "--domain", "taxi", "--out", str(out), "--db", str(base / "app.sqlite")])
    assert res.exit_code == 0, res.output
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert {"writer": "browser-test", "tree": {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}}.items() <= rows[-1].items()


def test_optimize_page_lists_runs_live_and_cancels(server, browser):
    url, _ = server
    import urllib.request

    def post(path, body=None):
        req = urllib.request.Request(url + path, method="POST", data=json.dumps(body or {}).encode(),
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=30) as res:
            return json.loads(res.read())

    page = browser.new_page(viewport={"width": 1280, "height": 900})
    page.goto(url + "/optimize")
    page.wait_for_load_state("networkidle")
    long = post("/api/runs", {"domain": "taxi", "steps": 100_000, "seed": 3,
                              "tree": {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "wait"}}})
    # the list shows the new run without a reload
    page.wait_for_selector(f"#runs li[data-run='{long['id']}']", timeout=10_000)
    page.click(f"#runs li[data-run='{long['id']}'] a")
    page.wait_for_function("document.querySelector('#status').textContent === 'running'", timeout=240_000)
    page.wait_for_function("/of 100,352 steps · about/.test(document.querySelector('#progress').textContent)", timeout=120_000)
    assert page.locator("#resume").is_hidden() and page.locator("#cancel").is_visible()
    page.click("#cancel")
    page.wait_for_function("document.querySelector('#status').textContent === 'cancelled'", timeout=30_000)
    page.wait_for_selector(f"#runs li[data-run='{long['id']}'][data-status='cancelled']", timeout=10_000)
    assert page.locator("#resume").is_visible() and page.locator("#cancel").is_hidden()
    page.on("dialog", lambda dialog: dialog.accept())
    page.click("#delete")
    page.wait_for_selector(f"#runs li[data-run='{long['id']}']", state="detached", timeout=10_000)
    page.wait_for_selector("#run-card", state="hidden", timeout=10_000)
    page.close()


def test_specify_domain_switch_edit_menu_and_back_forward(server, browser):
    url, _ = server
    page = browser.new_page(viewport={"width": 1100, "height": 900})
    page.goto(url + "/")
    page.fill("#description", DESCRIPTION)
    page.click("#translate")
    page.wait_for_selector("#tree svg g[data-slot='0']", timeout=120_000)
    assert "?spec=" in page.url
    root = page.get_attribute("#tree g[data-slot='0']", "data-id")

    # the edit menu offers only what the rules allow, and speaks of questions and answers
    page.click("#tree g[data-slot='1']")
    assert root not in page.eval_on_selector_all("#edit-choice option", "os => os.map(o => o.value)")
    place = page.inner_text("#edit-place")
    assert "answer to" in place and "Slot" not in place and "root" not in place
    # a new question keeps this box's action on its "yes" side and gets another one on "no"
    before = page.get_attribute("#tree g[data-slot='1']", "data-id")
    question = page.eval_on_selector("#edit-choice optgroup[label='Ask a question'] option", "o => o.value")
    page.select_option("#edit-choice", question)
    page.click("#apply-edit")
    page.wait_for_selector("#tree g[data-slot='3']")
    assert page.get_attribute("#tree g[data-slot='3']", "data-id") == before
    assert page.get_attribute("#tree g[data-slot='4']", "data-id") not in (before, None)
    assert page.inner_text("#edit-error") == ""

    # back and forward keep the tree
    page.goto(url + "/collect")
    page.go_back()
    page.wait_for_selector("#tree svg g[data-slot='3']", timeout=30_000)
    assert page.get_attribute("#tree g[data-slot='3']", "data-id") == before
    assert page.input_value("#description") == DESCRIPTION

    # another domain: the taxi tree is gone
    page.select_option("#domain", "highway")
    assert page.locator("#result").is_hidden() and page.inner_html("#tree") == ""
    page.close()


def test_pages_fit_a_phone_screen_and_work_offline(server, browser):
    url, _ = server
    page = browser.new_page(viewport={"width": 390, "height": 844})
    outside = []
    page.on("request", lambda req: outside.append(req.url) if not req.url.startswith(url) else None)
    page.goto(url + "/")
    page.fill("#description", DESCRIPTION)
    page.click("#translate")
    page.wait_for_selector("#tree svg g[data-slot='0']", timeout=120_000)
    with_tree = page.url
    for path in ("/", "/optimize", "/collect"):
        if path != "/":
            page.goto(url + path)
            page.wait_for_load_state("networkidle")
        width = page.evaluate("document.scrollingElement.scrollWidth")
        assert width <= 392, f"{path} is {width}px wide on a 390px screen"
    page.goto(with_tree)
    page.wait_for_selector("#tree svg g[data-slot='0']")
    assert page.locator("#tree-text").is_visible() and "yes:" in page.inner_text("#tree-text")  # the tree as text
    shoot(page, "specify-phone")
    page.set_viewport_size({"width": 1100, "height": 900})
    assert page.locator("#tree-text").is_hidden()
    page.set_viewport_size({"width": 1100, "height": 900})
    page.goto(url + "/docs")
    page.wait_for_selector("#endpoints h2")
    assert page.locator("#endpoints h2", has_text="POST /api/translate").count() == 1
    assert page.evaluate("document.querySelector('link[rel=icon]').href").endswith("favicon.svg")
    assert outside == []  # nothing loaded from the internet
    page.close()


EVIL_PAGE = """<!doctype html><title>another site</title><script>
async function attack(app, run, going) {
  const out = {};
  for (const [name, method, url, body] of [["resume", "POST", `/api/runs/${run}/resume`, null],
                                           ["start", "POST", "/api/runs", JSON.stringify(%s)],
                                           ["cancel", "POST", `/api/runs/${going}/cancel`, null],
                                           ["delete", "DELETE", `/api/runs/${run}`, null]]) {
    try {
      const r = await fetch(app + url, {method, body, headers: {"Content-Type": "text/plain"}, mode: "no-cors"});
      out[name] = r.type;
    } catch (e) { out[name] = "blocked: " + e.message; }
  }
  return out;
}
</script>"""


def test_a_page_on_another_origin_cannot_change_runs(server, browser):
    """A page served from a second loopback origin sends the "simple" cross-site requests a
    hostile site would (text/plain, no preflight); the app refuses them and nothing changes."""
    import http.server
    import urllib.request

    url, _ = server
    tree = {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}
    req = lambda method, path, body=None: json.loads(urllib.request.urlopen(urllib.request.Request(
        url + path, method=method, data=json.dumps(body).encode() if body is not None else None,
        headers={"Content-Type": "application/json"})).read())
    run = req("POST", "/api/runs", {"domain": "taxi", "tree": tree, "steps": 100_000})
    req("POST", f"/api/runs/{run['id']}/cancel")
    deadline = time.time() + 30
    while req("GET", f"/api/runs/{run['id']}")["status"] != "cancelled" and time.time() < deadline:
        time.sleep(0.2)  # a running run is cancelled once its trainer has ended
    going = req("POST", "/api/runs", {"domain": "taxi", "tree": tree, "steps": 100_000})
    while req("GET", f"/api/runs/{going['id']}")["status"] != "running" and time.time() < deadline:
        time.sleep(0.2)
    before = [(r["id"], r["status"]) for r in req("GET", "/api/runs")]
    page_html = (EVIL_PAGE % json.dumps({"domain": "taxi", "tree": tree, "steps": 512})).encode()

    class Page(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.end_headers()
            self.wfile.write(page_html)

        def log_message(self, *args):
            pass

    evil = http.server.HTTPServer(("127.0.0.1", free_port()), Page)
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    try:
        page = browser.new_page()
        page.goto(f"http://127.0.0.1:{evil.server_address[1]}/")
        sent = page.evaluate("([app, run, going]) => attack(app, run, going)", [url, run["id"], going["id"]])
        assert set(sent) == {"resume", "start", "cancel", "delete"}
    finally:
        evil.shutdown()
    time.sleep(1)
    assert [(r["id"], r["status"]) for r in req("GET", "/api/runs")] == before
    req("POST", f"/api/runs/{going['id']}/cancel")


def test_a_learned_threshold_reads_in_units_and_stays_in_the_editor(server, browser):
    """A tree handed back with a learned test (raw:gap_behind<0.2281) opens on the Specify page:
    the box reads in metres, the editor offers it as the slot's current question, and an edit
    elsewhere keeps it."""
    import httpx

    url, _ = server
    grid = ["raw:gap_behind<0.2281", "slower", "car_ahead_close", None, None, "slower", "idle"] + [None] * 8
    made = httpx.post(url + "/api/translate", json={"domain": "highway", "description": "Slow down when a car is close ahead."},
                      timeout=120).json()
    stored = httpx.put(f"{url}/api/specs/{made['spec_id']}", json={"domain": "highway", "grid": grid}, timeout=30)
    assert stored.status_code == 200, stored.text
    page = browser.new_page(viewport={"width": 1100, "height": 900})
    page.goto(f"{url}/?spec={made['spec_id']}")
    page.wait_for_selector("#tree svg g[data-slot='0']")
    assert "less than 22.8 m" in page.inner_text("#tree")
    page.click("#tree g[data-slot='0']")
    assert page.locator("#edit-choice option:checked").inner_text() == \
        "Is the gap to the car behind in my lane less than 22.8 m?"
    page.click("#tree g[data-slot='1']")
    assert "the “yes” answer to “Is the gap to the car behind in my lane less than 22.8 m?”" in page.inner_text("#edit-place")
    page.select_option("#edit-choice", "faster")
    page.click("#apply-edit")
    page.wait_for_function("document.querySelector('#tree g[data-slot=\"1\"]').dataset.id === 'faster'")
    assert page.locator("#tree g[data-slot='0']").get_attribute("data-id") == "raw:gap_behind<0.2281"
    assert page.inner_text("#edit-error") == ""
