"""A domain is one folder (issue 43): a copy of taxi's folder under a new name, outside the
package and found through NL2POLICY_DOMAINS, translates, evaluates, optimizes and appears in the
app, with no other file changed. Everything runs in a fresh process, as a user's would."""

import json
import os
import shutil
import subprocess
import sys
import textwrap

import pytest

from nl2policy.domains import get_domain

pytestmark = pytest.mark.train  # the optimize step runs PPO

SCRIPT = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    from fastapi.testclient import TestClient
    from typer.testing import CliRunner
    from nl2policy.app.server import create_app
    from nl2policy.cli import app
    from nl2policy.domains import DOMAINS, get_domain
    from nl2policy.language.translate import translate

    out, tmp = {}, Path(sys.argv[1])
    d = get_domain("rickshaw")
    out["domains"] = list(DOMAINS)
    out["folder"] = str(d.folder)
    out["env_id"] = d.env_id
    out["exact"] = d.exact is not None
    result = translate("rickshaw", "If I have a passenger I drive to the airport, otherwise I go to the city.")
    out["tree"] = result.to_json()["tree"]
    out["warnings"] = result.warnings
    runner = CliRunner()
    tree = json.dumps(out["tree"])
    ev = runner.invoke(app, ["evaluate", "--domain", "rickshaw", "--tree", tree, "--episodes", "5"])
    out["evaluate"] = [ev.exit_code, ev.output[-300:]]
    op = runner.invoke(app, ["optimize", "--domain", "rickshaw", "--tree", tree, "--steps", "1024", "--out", str(tmp / "run")])
    out["optimize"] = [op.exit_code, op.output[-300:]]
    with TestClient(create_app(tmp / "a.sqlite", tmp, results_dir=tmp), base_url="http://127.0.0.1") as client:
        out["app"] = client.get("/api/domains").json()["rickshaw"]["title"]
    print(json.dumps(out))
""")


def test_a_copied_domain_folder_is_a_new_domain_with_no_other_file_changed(tmp_path):
    robots = tmp_path / "robots"
    shutil.copytree(get_domain("taxi").folder, robots / "rickshaw", ignore=shutil.ignore_patterns("__pycache__"))
    env = {**os.environ, "NL2POLICY_DOMAINS": str(robots), "NL2POLICY_HOME": str(tmp_path / "home")}
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path)], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["domains"][-1] == "rickshaw" and "taxi" in out["domains"]
    assert out["folder"] == str(robots / "rickshaw")
    assert out["env_id"] == "nl2policy/rickshaw-v0" and out["exact"]  # its own env id; its own copy of the exact model
    assert out["tree"] == {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}
    assert not any("domain" in w for w in out["warnings"]), out["warnings"]  # on topic: the copy's own words
    assert out["evaluate"][0] == 0, out["evaluate"]
    assert out["optimize"][0] == 0, out["optimize"]
    assert (tmp_path / "run" / "summary.json").is_file()
    assert out["app"] == "Taxi"


def test_a_domain_folder_that_shadows_a_built_in_one_is_refused_in_one_line(tmp_path):
    robots = tmp_path / "robots"
    shutil.copytree(get_domain("taxi").folder, robots / "taxi", ignore=shutil.ignore_patterns("__pycache__"))
    env = {**os.environ, "NL2POLICY_DOMAINS": str(robots)}
    code = "import sys; from nl2policy.cli import main; sys.exit(main())"
    proc = subprocess.run([sys.executable, "-c", code, "translate", "--domain", "taxi", "go to the city"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode != 0 and "domain 'taxi'" in proc.stderr and "already" in proc.stderr
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_a_broken_spec_in_a_users_folder_is_one_line_not_a_traceback(tmp_path):
    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "spec.toml").write_text("not = [toml")
    env = {**os.environ, "NL2POLICY_DOMAINS": str(tmp_path)}
    code = "import sys; from nl2policy.cli import main; sys.exit(main())"
    proc = subprocess.run([sys.executable, "-c", code, "translate", "--domain", "taxi", "go to the city"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [proc.stderr.strip()] and "robot/spec.toml: cannot be read" in proc.stderr
