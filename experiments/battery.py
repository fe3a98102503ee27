"""The hostile-input battery: what a careless user, a hostile page, a broken disk or another
process can throw at the web app and the CLI, run against the real executables; it counts
responses with status 500, tracebacks (in a response, in the server's log, on the CLI's stderr)
and hangs (no answer within a case's deadline).

    .venv/bin/python -m experiments.battery --out results/robustness

Writes OUT/battery.md (the totals, by kind of case) and OUT/battery_cases.jsonl (every case,
what was sent and what came back). Exits 1 if any case gave a 500, a traceback or a hang.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Optional

import httpx

TREE = {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}
DEEP = '{"do": "wait"}'
for _ in range(3000):
    DEEP = f'{{"if": "at_city", "yes": {DEEP}, "no": {{"do": "wait"}}}}'


@dataclass
class Case:
    kind: str
    name: str
    status: Optional[int] = None  # HTTP status, or the CLI's exit code
    seconds: float = 0.0
    hang: bool = False
    traceback: bool = False
    note: str = ""
    expect: str = ""  # what a correct answer is, in words
    ok: bool = True  # the expectation held (beyond no 500 / traceback / hang)
    extra: dict = field(default_factory=dict)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """`nl2policy serve` in a fresh data folder, its stderr kept for tracebacks."""

    def __init__(self, base: Path) -> None:
        self.base, self.port = base, free_port()
        self.log = open(base / "server.log", "wb")
        env = {**os.environ, "NL2POLICY_HOME": str(base)}
        self.proc = subprocess.Popen([sys.executable, "-m", "nl2policy.cli", "serve", "--port", str(self.port),
                                      "--data-dir", str(base)], stdout=self.log, stderr=subprocess.STDOUT, env=env)
        self.url = f"http://127.0.0.1:{self.port}"
        deadline = time.time() + 60
        while time.time() < deadline:
            try:
                httpx.get(self.url + "/api/domains", timeout=2)
                return
            except httpx.HTTPError:
                time.sleep(0.2)
        raise RuntimeError("the server did not start")

    def tracebacks(self) -> int:
        return (self.base / "server.log").read_bytes().count(b"Traceback")

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=30)
        self.log.close()


def http_case(server: Server, kind: str, name: str, method: str, path: str, *, body: Optional[bytes] = None,
              headers: Optional[dict] = None, expect: Callable[[httpx.Response], bool] = lambda r: r.status_code < 500,
              expect_words: str = "a 4xx or 2xx with a JSON message", timeout: float = 60) -> Case:
    case = Case(kind, name, expect=expect_words)
    before = server.tracebacks()
    start = time.time()
    try:
        r = httpx.request(method, server.url + path, content=body, headers=headers or {}, timeout=timeout)
        case.status = r.status_code
        case.traceback = "Traceback" in r.text
        case.ok = expect(r)
        case.note = r.text[:160]
    except httpx.TimeoutException:
        case.hang = True
    except httpx.HTTPError as exc:
        case.note = f"connection: {type(exc).__name__}"
        case.ok = False
    case.seconds = round(time.time() - start, 2)
    case.traceback = case.traceback or server.tracebacks() > before
    return case


JSON = {"Content-Type": "application/json"}
status_in = lambda *codes: (lambda r: r.status_code in codes)


def api_cases(server: Server) -> list[Case]:
    out: list[Case] = []
    run = httpx.post(server.url + "/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512}, timeout=60).json()
    spec = httpx.post(server.url + "/api/translate", json={"domain": "taxi", "description": "go to the city"}, timeout=120).json()
    rid, sid = run["id"], spec["spec_id"]
    posts = {"translate": ("POST", "/api/translate"), "validate": ("POST", "/api/validate"), "runs": ("POST", "/api/runs"),
             "submissions": ("POST", "/api/submissions"), "edit spec": ("PUT", f"/api/specs/{sid}")}
    bodies = {
        "empty body": b"", "null": b"null", "a list": b"[]", "empty object": b"{}", "binary": bytes(range(256)) * 4,
        "invalid UTF-8": b'{"domain": "taxi", "description": "\xff\xfe"}', "not JSON": b"{domain: taxi",
        "deep nesting": ('{"domain": "taxi", "tree": ' + DEEP + "}").encode(), "huge number": b'{"domain": "taxi", "steps": 1e400}',
        "NaN": b'{"domain": "taxi", "tree": {"do": "wait"}, "steps": NaN}', "unknown domain": b'{"domain": "mars", "description": "x"}',
    }
    surrogate_fields = {"translate": '{"domain": "taxi", "description": "\\ud800"}',
                        "validate": '{"domain": "taxi", "tree": {"do": "\\ud800"}}',
                        "runs": '{"domain": "taxi", "tree": {"do": "wait"}, "steps": "\\ud800"}',
                        "submissions": '{"domain": "taxi", "writer": "\\ud800", "grid": ["wait"], "description": "wait"}',
                        "edit spec": '{"domain": "taxi", "tree": {"do": "\\udfff"}}'}
    for endpoint, (method, path) in posts.items():
        for name, body in bodies.items():
            out.append(http_case(server, "malformed body", f"{endpoint}: {name}", method, path, body=body, headers=JSON))
        out.append(http_case(server, "text that is not Unicode", f"{endpoint}: lone surrogate", method, path,
                             body=surrogate_fields[endpoint].encode(), headers=JSON, expect=status_in(422),
                             expect_words="422, the input not echoed"))
        out.append(http_case(server, "cross-site", f"{endpoint}: text/plain from another origin", method, path,
                             body=b'{"domain": "taxi"}', headers={"Content-Type": "text/plain", "Origin": "http://evil.example"},
                             expect=status_in(403), expect_words="403"))
        out.append(http_case(server, "cross-site", f"{endpoint}: JSON as text/plain, no origin", method, path,
                             body=b'{"domain": "taxi"}', headers={"Content-Type": "text/plain"}, expect=status_in(415),
                             expect_words="415"))
    for action, method, path in [("cancel", "POST", f"/api/runs/{rid}/cancel"), ("resume", "POST", f"/api/runs/{rid}/resume"),
                                 ("delete", "DELETE", f"/api/runs/{rid}"), ("start", "POST", "/api/runs")]:
        for label, headers in [("Origin evil", {"Origin": "http://evil.example", "Content-Type": "text/plain"}),
                               ("Origin null", {"Origin": "null"}), ("Sec-Fetch-Site cross-site", {"Sec-Fetch-Site": "cross-site"}),
                               ("another port", {"Origin": "http://127.0.0.1:1"})]:
            out.append(http_case(server, "cross-site", f"{action}: {label}", method, path, headers=headers,
                                 expect=status_in(403), expect_words="403, nothing changed"))
    for name, text in [("zero-width only", "\u200b\u200d\ufeff"), ("spaces only", "   \n\t"), ("punctuation only", "?!.,;"),
                       ("5,001 characters", "a" * 5001), ("NUL bytes", "go\x00 to the city")]:
        out.append(http_case(server, "description", name, "POST", "/api/translate",
                             body=json.dumps({"domain": "taxi", "description": text}).encode(), headers=JSON,
                             expect=status_in(200, 422) if "NUL" in name else status_in(422), expect_words="422 (NUL: 200 or 422)"))
    vague = "go somewhere depending on things"
    for name, answers in [("answers not a list", "wait"), ("answers an object", {"do": "wait"}), ("a null answer", [None]),
                          ("an answer without a situation", [{"do": "wait"}]), ("an unknown action", [{"situation": {}, "do": "fly"}]),
                          ("a situation the domain forbids", [{"situation": {"at_airport": True, "at_city": True}, "do": "wait"}]),
                          ("1,000 answers", [{"situation": {}, "do": "wait"}] * 1000),
                          ("a lone surrogate in an action", '[{"situation": {}, "do": "\\ud800"}]')]:
        text = answers if isinstance(answers, str) and answers.startswith("[") else json.dumps(answers)
        out.append(http_case(server, "answers", name, "POST", "/api/translate", headers=JSON, expect=status_in(422),
                             expect_words="422 naming the answers",
                             body=f'{{"domain": "taxi", "description": "{vague}", "answers": {text}}}'.encode()))
    for name, writer in [("whitespace writer", "   "), ("zero-width writer", "\u200b"), ("61-character writer", "w" * 61)]:
        out.append(http_case(server, "submission", name, "POST", "/api/submissions", expect=status_in(422), expect_words="422",
                             body=json.dumps({"domain": "taxi", "writer": writer, "grid": ["wait"] + [None] * 14,
                                              "description": "wait"}).encode(), headers=JSON))
    for name, steps in [("string steps", "many"), ("negative steps", -5), ("1e20 steps", 10**20), ("float steps", 2.5),
                        ("too few steps", 1), ("bool steps", True)]:
        out.append(http_case(server, "run request", name, "POST", "/api/runs", headers=JSON, expect=status_in(422),
                             expect_words="422", body=json.dumps({"domain": "taxi", "tree": TREE, "steps": steps}).encode()))
    for name, path in [("surrogate in a path", "/api/runs/%ED%A0%80"), ("1,000-character id", "/api/runs/" + "x" * 1000),
                       ("SQL in an id", "/api/specs/'%3B%20DROP%20TABLE%20runs%3B--"), ("unknown page", "/nothing"),
                       ("unknown domain briefing", "/api/briefing/mars"), ("dot-dot static", "/static/..%2F..%2Fserver.py"),
                       ("policy of an unfinished run", f"/api/runs/{rid}/policy")]:
        out.append(http_case(server, "paths", name, "GET", path, expect=status_in(400, 404, 409, 422), expect_words="404/409/422"))
    out.append(http_case(server, "host", "DNS rebinding Host", "GET", "/api/domains", headers={"Host": "evil.example"},
                         expect=status_in(400), expect_words="400"))
    out.append(raw_case(server, "size", "Content-Length over the limit", b"POST /api/translate HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                        b"Content-Type: application/json\r\nContent-Length: 5000000\r\n\r\nxxxxxxxxxx", 413))
    out.append(raw_case(server, "size", "Content-Length not a number", b"POST /api/translate HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                        b"Content-Type: application/json\r\nContent-Length: lots\r\n\r\nxxxxxxxxxx", 400, 413))
    out.append(http_case(server, "size", "chunked body over the limit", "POST", "/api/translate", headers=JSON,
                         body=iter([b"x" * 65536] * 20), expect=status_in(413), expect_words="413"))  # type: ignore[arg-type]
    for path in ("/", "/optimize", "/api/domains", "/api/runs/none"):
        out.append(http_case(server, "headers", f"security headers on {path}", "GET", path,
                             expect=lambda r: r.headers.get("x-frame-options") == "DENY"
                             and r.headers.get("x-content-type-options") == "nosniff"
                             and "frame-ancestors 'none'" in r.headers.get("content-security-policy", ""),
                             expect_words="nosniff, DENY, frame-ancestors 'none'"))
    return out


def raw_case(server: Server, kind: str, name: str, request: bytes, *codes: int, deadline: float = 60) -> Case:
    """A request written byte for byte (a client library would refuse to send it)."""
    case = Case(kind, name, expect=" or ".join(map(str, codes)))
    before, start = server.tracebacks(), time.time()
    with socket.create_connection(("127.0.0.1", server.port), timeout=deadline) as s:
        s.sendall(request)
        reply = b""
        try:
            while b"\r\n\r\n" not in reply and (chunk := s.recv(4096)):
                reply += chunk
        except socket.timeout:
            case.hang = True
    case.seconds = round(time.time() - start, 2)
    case.status = int(reply.split()[1]) if reply.startswith(b"HTTP/") else None
    case.ok, case.traceback = case.status in codes, server.tracebacks() > before
    return case


def slow_body_case(server: Server, deadline: float = 60) -> Case:
    """Half a body, then silence: the server must answer 408 and close, not hold the connection."""
    case = Case("slow body", "half a body, then nothing", expect="408 and the connection closed")
    start = time.time()
    with socket.create_connection(("127.0.0.1", server.port), timeout=deadline) as s:
        s.sendall(b"POST /api/translate HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                  b"Content-Length: 100\r\n\r\n{\"domain\":")
        reply = b""
        try:
            while chunk := s.recv(4096):
                reply += chunk
        except socket.timeout:
            case.hang = True
    case.seconds = round(time.time() - start, 1)
    case.status = int(reply.split()[1]) if reply.startswith(b"HTTP/") else None
    case.ok = case.status == 408
    return case


def concurrent_first_case(base: Path) -> Case:
    """Eight translations at once on a server that has loaded nothing yet."""
    server = Server(base)
    case = Case("concurrency", "8 first translations at once on a fresh server", expect="8 x 200")
    codes: list[int] = []
    start, gate = time.time(), threading.Barrier(8)

    def post(i: int) -> None:
        gate.wait()
        try:
            r = httpx.post(server.url + "/api/translate", json={"domain": "taxi" if i % 2 else "highway",
                                                              "description": "If I have a passenger I go to the airport."}, timeout=180)
            codes.append(r.status_code)
        except httpx.TimeoutException:
            case.hang = True

    threads = [threading.Thread(target=post, args=(i,)) for i in range(8)]
    [t.start() for t in threads]
    [t.join() for t in threads]
    case.seconds, case.status = round(time.time() - start, 1), max(codes) if codes else None
    case.ok, case.traceback, case.extra = codes == [200] * 8, server.tracebacks() > 0, {"codes": codes}
    server.stop()
    return case


def store_fault_cases(server: Server) -> list[Case]:
    """A 35-second exclusive lock by another process, then a damaged file restored: a run
    queued after each must start within 30 s."""
    out = []
    db = server.base / "nl2policy.sqlite"

    def queue_and_wait(case: Case) -> None:
        run = httpx.post(server.url + "/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512}, timeout=60).json()
        t0 = time.time()
        while time.time() - t0 < 30:
            if httpx.get(f"{server.url}/api/runs/{run['id']}", timeout=60).json()["status"] != "queued":
                case.seconds, case.ok = round(time.time() - t0, 1), True
                return
            time.sleep(0.2)
        case.ok, case.hang, case.seconds = False, True, 30.0

    before = server.tracebacks()
    lock = Case("database faults", "35-second lock by another process, then a run", expect="starts within 30 s")
    locker = subprocess.Popen([sys.executable, "-c", f"import sqlite3, time; db = sqlite3.connect({str(db)!r}, isolation_level=None); "
                               "db.execute('BEGIN EXCLUSIVE'); print('locked', flush=True); time.sleep(35); db.execute('COMMIT')"],
                              stdout=subprocess.PIPE, text=True)
    locker.stdout.readline()
    during = http_case(server, "database faults", "a request during the lock", "GET", "/api/runs",
                       expect=status_in(200, 503), expect_words="503 (or 200 once the lock ends)")
    locker.wait(timeout=60)
    queue_and_wait(lock)
    lock.traceback = server.tracebacks() > before
    out += [during, lock]
    damaged = Case("database faults", "file damaged under the server, then restored, then a run", expect="starts within 30 s")
    with sqlite3.connect(db) as conn:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    good = db.read_bytes()
    db.write_bytes(b"\0" * 100 + os.urandom(len(good) - 100))
    time.sleep(3)
    out.append(http_case(server, "database faults", "a request while the file is damaged", "GET", "/api/runs",
                         expect=status_in(503), expect_words="503"))
    db.write_bytes(good)
    queue_and_wait(damaged)
    damaged.traceback = server.tracebacks() > before
    out.append(damaged)
    return out


def cli_cases(base: Path) -> list[Case]:
    out = []
    installed = Path(sys.executable).with_name("nl2policy")  # the executable a user runs
    command = [str(installed).encode()] if installed.is_file() else \
        [sys.executable.encode(), b"-c", b"import sys; from nl2policy.cli import main; sys.exit(main())"]
    tree = json.dumps(TREE).encode()
    (base / "bin.json").write_bytes(bytes(range(256)) * 8)
    (base / "deep.json").write_text(DEEP)
    cases = [
        ("invalid UTF-8 in argv", [b"translate", b"--domain", b"taxi", b"go to the \xff city"], {}),
        ("zero-width description", [b"translate", b"--domain", b"taxi", "\u200b\u200b".encode()], {}),
        ("empty description", [b"translate", b"--domain", b"taxi", b""], {}),
        ("--answer not JSON", [b"translate", b"--domain", b"taxi", b"--answer", b"{situation", b"go somewhere"], {}),
        ("--answer with an unknown action", [b"translate", b"--domain", b"taxi", b"--answer",
                                             b'{"situation": {}, "do": "fly"}', b"go somewhere"], {}),
        ("train-translator into an unwritable folder", [b"train-translator", b"--domain", b"taxi", b"--out", b"/proc/nl2policy"], {}),
        ("NL2POLICY_CORPUS missing", [b"train-translator", b"--domain", b"taxi", b"--out", str(base / "models").encode()],
         {"NL2POLICY_CORPUS": str(base / "none")}),
        ("NL2POLICY_HOME unwritable", [b"serve", b"--port", str(free_port()).encode()], {"NL2POLICY_HOME": "/proc/nl2policy"}),
        ("1e20 optimize steps", [b"optimize", b"--domain", b"taxi", b"--tree", tree, b"--steps", b"100000000000000000000"], {}),
        ("1e10 evaluate episodes", [b"evaluate", b"--domain", b"taxi", b"--tree", tree, b"--episodes", b"10000000000"], {}),
        ("zero episodes", [b"compare", b"--episodes", b"0"], {}),
        ("unknown command", [b"launch"], {}),
        ("unknown domain", [b"evaluate", b"--domain", b"mars", b"--tree", tree], {}),
        ("binary tree file", [b"evaluate", b"--domain", b"taxi", b"--tree", str(base / "bin.json").encode()], {}),
        ("3000-deep tree", [b"evaluate", b"--domain", b"taxi", b"--tree", str(base / "deep.json").encode()], {}),
        ("negative seed", [b"evaluate", b"--domain", b"taxi", b"--tree", tree, b"--seed", b"-1"], {}),
        ("optimize --out a file", [b"optimize", b"--domain", b"taxi", b"--tree", tree, b"--out", str(base / "bin.json").encode()], {}),
        ("port 0", [b"serve", b"--port", b"0"], {}),
        ("surrogate in a tree", [b"evaluate", b"--domain", b"taxi", b"--tree", b'{"do": "\xed\xa0\x80"}'], {}),
    ]
    for name, args, env in cases:
        case = Case("CLI", name, expect="exit 2 and one line 'error: ...'")
        start = time.time()
        try:
            proc = subprocess.run([*command, *args], capture_output=True, timeout=120,
                                  env={**os.environ, "NL2POLICY_HOME": str(base / "home"), **env})
            stderr = proc.stderr.decode(errors="replace")
            lines = [ln for ln in stderr.splitlines() if ln.strip() and not ln.startswith("note:")]
            case.status, case.traceback = proc.returncode, "Traceback" in stderr
            case.ok = proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:")
            case.note = lines[0][:160] if lines else ""
        except subprocess.TimeoutExpired:
            case.hang = True
        case.seconds = round(time.time() - start, 1)
        out.append(case)
    return out


def report(cases: list[Case], out: Path, command: str) -> bool:
    out.mkdir(parents=True, exist_ok=True)
    with (out / "battery_cases.jsonl").open("w") as fh:
        for c in cases:
            fh.write(json.dumps(asdict(c)) + "\n")
    kinds = sorted({c.kind for c in cases}, key=[c.kind for c in cases].index)
    fives = sum(c.status == 500 for c in cases if c.kind != "CLI")
    tracebacks, hangs = sum(c.traceback for c in cases), sum(c.hang for c in cases)
    off = [c for c in cases if not c.ok and not c.hang]
    lines = [f"# Hostile-input battery\n", f"Made by: `{command}`  ",
             f"On: {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, against `nl2policy serve` and the `nl2policy` executable  ",
             "Every case, what was sent and what came back: `battery_cases.jsonl`\n",
             f"**{len(cases)} cases: {fives} responses with status 500, {tracebacks} tracebacks, {hangs} hangs; "
             f"{len(off)} answers other than expected.**\n",
             "| kind | cases | 500s | tracebacks | hangs | as expected | slowest (s) |", "|---|---:|---:|---:|---:|---:|---:|"]
    for k in kinds:
        group = [c for c in cases if c.kind == k]
        lines.append(f"| {k} | {len(group)} | {sum(c.status == 500 for c in group if k != 'CLI')} | "
                     f"{sum(c.traceback for c in group)} | {sum(c.hang for c in group)} | {sum(c.ok for c in group)} | "
                     f"{max(c.seconds for c in group):.1f} |")
    if off:
        lines += ["", "Answers other than expected:", ""] + [f"- {c.kind} / {c.name}: {c.status} ({c.note[:120]})" for c in off]
    (out / "battery.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return fives == 0 and tracebacks == 0 and hangs == 0 and not off


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results/robustness"))
    args = parser.parse_args()
    command = f"python -m experiments.battery --out {args.out}"
    with tempfile.TemporaryDirectory(prefix="battery-") as tmp:
        base = Path(tmp)
        (base / "app").mkdir()
        (base / "fresh").mkdir()
        (base / "cli").mkdir()
        cases = [concurrent_first_case(base / "fresh")]
        server = Server(base / "app")
        try:
            cases += api_cases(server)
            cases.append(slow_body_case(server))
            cases += store_fault_cases(server)
        finally:
            server.stop()
        cases += cli_cases(base / "cli")
    sys.exit(0 if report(cases, args.out, command) else 1)


if __name__ == "__main__":
    main()
