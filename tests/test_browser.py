"""End to end in a real browser (Playwright driving Debian's chromium, headless): describe,
see the tree, edit a node, optimize briefly, see the curve and the final tree; build and
submit a tree on the Collect page and find it in the export.

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
    page.wait_for_function("document.querySelector('#status').textContent === 'finished'", timeout=240_000)
    page.wait_for_selector("#curve polyline[data-name='run']")
    page.wait_for_selector("#final svg")
    assert page.locator("#initial svg").count() == 1
    assert page.locator("#download").is_visible()
    shoot(page, "optimize")
    page.close()


def test_collect_build_submit_and_export(server, browser):
    url, base = server
    page = browser.new_page(viewport={"width": 1100, "height": 1000})
    page.goto(url + "/collect")
    page.wait_for_selector("#palette span")
    page.select_option("#domain", "taxi")
    page.wait_for_selector("#palette span[data-id='has_passenger']")
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
    shoot(page, "collect")
    page.click("#submit")
    page.wait_for_function("document.querySelector('#ok').textContent.startsWith('Thank you')")
    page.close()

    from nl2policy.cli import app

    out = base / "export.jsonl"
    res = CliRunner().invoke(app, ["export-submissions", "--domain", "taxi", "--out", str(out), "--db", str(base / "app.sqlite")])
    assert res.exit_code == 0, res.output
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert {"writer": "browser-test", "tree": {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}}.items() <= rows[-1].items()
