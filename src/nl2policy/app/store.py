"""SQLite storage for what the app must never lose: specifications, optimization runs and
collected corpus submissions.

Every write is one transaction; the database runs in WAL mode so pages can read while a run
writes, and each call opens its own connection, so concurrent requests never share one.

Opening checks the file first (`StoreError` names it and says what to do): an empty, garbage,
truncated or damaged file is refused, never replaced by a fresh empty database, since the user's
specifications and runs may be recoverable from it.
"""

from __future__ import annotations

import json
import sqlite3
import time
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Optional

SCHEMA = """
CREATE TABLE IF NOT EXISTS specs (
    id TEXT PRIMARY KEY, domain TEXT NOT NULL, description TEXT NOT NULL,
    tree TEXT NOT NULL, translated_tree TEXT NOT NULL, confidence REAL,
    warnings TEXT NOT NULL DEFAULT '[]', node_confidence TEXT NOT NULL DEFAULT '{}',
    created REAL NOT NULL, updated REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS runs (
    id TEXT PRIMARY KEY, domain TEXT NOT NULL, spec_id TEXT, tree TEXT NOT NULL,
    steps INTEGER NOT NULL, seed INTEGER NOT NULL, status TEXT NOT NULL,
    out_dir TEXT NOT NULL, summary TEXT, error TEXT, created REAL NOT NULL, updated REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS submissions (
    id TEXT PRIMARY KEY, domain TEXT NOT NULL, writer TEXT NOT NULL, tree TEXT NOT NULL,
    description TEXT NOT NULL, created REAL NOT NULL
);
"""

BUSY_TIMEOUT_S = 30.0
"""How long a request waits for another writer's lock before the store reports a fault (SQLite's
busy timeout); read at every connection."""

RUN_STATES = ("queued", "running", "finished", "failed", "interrupted", "cancelled")
WAITING = ("queued", "running")


class StoreError(Exception):
    """The database file cannot be used; the message names it and says what to do."""


def _damaged(path: Path, what: str) -> StoreError:
    return StoreError(f"the database {path} {what}; nothing was changed. Move it aside (e.g. to {path.name}.damaged) "
                      "to start a new, empty database, or restore it from a backup")


def _unwritable(path: Path, reason: str) -> StoreError:
    return StoreError(f"cannot write the database {path}: {reason}; make its folder writable, or set NL2POLICY_HOME "
                      "(or --db) to a writable place")


class Store:
    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        if self.path.is_dir():
            raise StoreError(f"the database path {self.path} is a folder; give a file (e.g. {self.path / 'nl2policy.sqlite'})")
        if self.path.is_file() and self.path.stat().st_size == 0:
            raise _damaged(self.path, "is an empty file (0 bytes), not an nl2policy database")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise _unwritable(self.path, exc.strerror or str(exc)) from exc
        try:
            db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S)
        except sqlite3.Error as exc:
            raise _unwritable(self.path, str(exc)) from exc
        try:
            check = db.execute("PRAGMA quick_check").fetchone()[0]
            if check != "ok":
                raise _damaged(self.path, f"is damaged (SQLite's check says: {check[:200]})")
            db.execute("PRAGMA journal_mode=WAL")
            db.executescript(SCHEMA)
            db.commit()
        except sqlite3.OperationalError as exc:
            if "readonly" in str(exc) or "unable to open" in str(exc) or "disk I/O" in str(exc):
                raise _unwritable(self.path, str(exc)) from exc
            raise _damaged(self.path, f"cannot be read ({exc})") from exc
        except sqlite3.DatabaseError as exc:  # "file is not a database", "disk image is malformed"
            raise _damaged(self.path, f"is not a readable SQLite database ({exc})") from exc
        finally:
            db.close()

    @contextmanager
    def _connect(self) -> Iterator[sqlite3.Connection]:
        db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
        db.row_factory = sqlite3.Row
        try:
            db.execute("BEGIN IMMEDIATE")
            yield db
            db.execute("COMMIT")
        except BaseException:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise
        finally:
            db.close()

    # specifications -----------------------------------------------------------------------
    def add_spec(self, domain: str, description: str, tree: dict, confidence: Optional[float],
                 warnings: list[str], node_confidence: dict) -> dict:
        now = time.time()
        spec_id = uuid.uuid4().hex[:12]
        with self._connect() as db:
            db.execute(
                "INSERT INTO specs VALUES (?,?,?,?,?,?,?,?,?,?)",
                (spec_id, domain, description, json.dumps(tree), json.dumps(tree), confidence,
                 json.dumps(warnings), json.dumps(node_confidence), now, now))
        return self.get_spec(spec_id)

    def update_spec_tree(self, spec_id: str, tree: dict, node_confidence: Optional[dict] = None) -> Optional[dict]:
        """A new tree for a spec; `node_confidence` replaces the translator's per-node confidences
        (an edited node has none: the translator never proposed it)."""
        with self._connect() as db:
            cur = db.execute("UPDATE specs SET tree=?, node_confidence=COALESCE(?, node_confidence), updated=? WHERE id=?",
                             (json.dumps(tree), None if node_confidence is None else json.dumps(node_confidence),
                              time.time(), spec_id))
            if cur.rowcount == 0:
                return None
        return self.get_spec(spec_id)

    def get_spec(self, spec_id: str) -> Optional[dict]:
        with self._connect() as db:
            row = db.execute("SELECT * FROM specs WHERE id=?", (spec_id,)).fetchone()
        return _spec(row) if row else None

    def list_specs(self, limit: int = 50) -> list[dict]:
        with self._connect() as db:
            rows = db.execute("SELECT * FROM specs ORDER BY created DESC LIMIT ?", (limit,)).fetchall()
        return [_spec(r) for r in rows]

    # optimization runs --------------------------------------------------------------------
    def add_run(self, domain: str, tree: dict, steps: int, seed: int, runs_dir: Path, spec_id: Optional[str]) -> dict:
        now = time.time()
        run_id = uuid.uuid4().hex[:12]
        out_dir = str(Path(runs_dir) / run_id)
        with self._connect() as db:
            db.execute("INSERT INTO runs VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
                       (run_id, domain, spec_id, json.dumps(tree), steps, seed, "queued", out_dir, None, None, now, now))
        return self.get_run(run_id)

    def set_run_status(self, run_id: str, status: str, summary: Optional[dict] = None, error: Optional[str] = None) -> None:
        if status not in RUN_STATES:
            raise ValueError(f"unknown run state {status!r}")
        with self._connect() as db:
            db.execute("UPDATE runs SET status=?, summary=COALESCE(?, summary), error=?, updated=? WHERE id=?",
                       (status, json.dumps(summary) if summary is not None else None, error, time.time(), run_id))

    def get_run(self, run_id: str) -> Optional[dict]:
        with self._connect() as db:
            row = db.execute("SELECT * FROM runs WHERE id=?", (run_id,)).fetchone()
        return _run(row) if row else None

    def list_runs(self, status: Optional[str] = None, limit: int = 50) -> list[dict]:
        with self._connect() as db:
            if status:
                rows = db.execute("SELECT * FROM runs WHERE status=? ORDER BY created LIMIT ?", (status, limit)).fetchall()
            else:
                rows = db.execute("SELECT * FROM runs ORDER BY created DESC LIMIT ?", (limit,)).fetchall()
        return [_run(r) for r in rows]

    def count_runs(self, statuses: tuple[str, ...]) -> int:
        with self._connect() as db:
            marks = ",".join("?" * len(statuses))
            return db.execute(f"SELECT COUNT(*) FROM runs WHERE status IN ({marks})", statuses).fetchone()[0]

    def delete_run(self, run_id: str) -> bool:
        with self._connect() as db:
            return db.execute("DELETE FROM runs WHERE id=?", (run_id,)).rowcount > 0

    # collected submissions ----------------------------------------------------------------
    def add_submission(self, domain: str, writer: str, tree: dict, description: str) -> dict:
        sub_id = uuid.uuid4().hex[:12]
        with self._connect() as db:
            db.execute("INSERT INTO submissions VALUES (?,?,?,?,?,?)",
                       (sub_id, domain, writer, json.dumps(tree), description, time.time()))
        return {"id": sub_id, "domain": domain, "writer": writer, "tree": tree, "description": description}

    def list_submissions(self, domain: Optional[str] = None) -> list[dict]:
        with self._connect() as db:
            if domain:
                rows = db.execute("SELECT * FROM submissions WHERE domain=? ORDER BY created", (domain,)).fetchall()
            else:
                rows = db.execute("SELECT * FROM submissions ORDER BY created").fetchall()
        return [{"id": r["id"], "domain": r["domain"], "writer": r["writer"], "tree": json.loads(r["tree"]),
                 "description": r["description"], "created": r["created"]} for r in rows]


def _spec(row: sqlite3.Row) -> dict[str, Any]:
    return {
        "id": row["id"], "domain": row["domain"], "description": row["description"],
        "tree": json.loads(row["tree"]), "translated_tree": json.loads(row["translated_tree"]),
        "confidence": row["confidence"], "warnings": json.loads(row["warnings"]),
        "node_confidence": json.loads(row["node_confidence"]), "created": row["created"], "updated": row["updated"],
    }


def _run(row: sqlite3.Row) -> dict[str, Any]:
    return {
        "id": row["id"], "domain": row["domain"], "spec_id": row["spec_id"], "tree": json.loads(row["tree"]),
        "steps": row["steps"], "seed": row["seed"], "status": row["status"], "out_dir": row["out_dir"],
        "summary": json.loads(row["summary"]) if row["summary"] else None, "error": row["error"],
        "created": row["created"], "updated": row["updated"],
    }
