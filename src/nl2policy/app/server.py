"""The FastAPI app: a JSON API (with its OpenAPI schema at /docs) for every page action, and
three pages (Specify, Optimize, Collect) served as static HTML + JS that call it.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import sqlite3
import threading
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any, Callable, Optional

from fastapi import FastAPI, HTTPException, Request
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field

from nl2policy.app import guards, outcome
from nl2policy.app.places import place
from nl2policy.app.baselines import baseline_curves
from nl2policy.app.runlock import holder
from nl2policy.app.runs import RunManager, read_curve
from nl2policy.app.store import WAITING, Store
from nl2policy.domains import DOMAINS, get_domain
from nl2policy.limits import (MAX_BODY_BYTES, MAX_DESCRIPTION, MAX_SEED, MAX_STEPS, MAX_WAITING_RUNS, description_problem,
                              has_visible, steps_problem)
from nl2policy.trees import GRID_SLOTS, TreeError, from_grid, parse_tree, to_grid, to_svg, to_text, tree_to_json

STATIC = Path(__file__).resolve().parent / "static"
LOW_CONFIDENCE = 0.5


class TranslateIn(BaseModel):
    domain: str
    description: str = Field(..., max_length=MAX_DESCRIPTION)
    answers: list[Any] = Field(default_factory=list, max_length=10,
                               description='answers to the questions asked so far, in order: {"situation": {question: bool}, "do": action}')
    max_questions: int = Field(3, ge=0, le=10, description="questions the translator may ask about this description")


class TreeIn(BaseModel):
    domain: str
    tree: Optional[Any] = None  # corpus tree JSON ...
    grid: Optional[list[Optional[str]]] = None  # ... or the 15-slot grid


class RunIn(BaseModel):
    domain: str
    tree: Any
    steps: int = Field(20_000, ge=1, le=MAX_STEPS)
    seed: int = Field(0, ge=0, le=MAX_SEED)
    spec_id: Optional[str] = None


class SubmissionIn(BaseModel):
    domain: str
    writer: str = Field(..., min_length=1, max_length=60)
    grid: list[Optional[str]]
    description: str = Field(..., min_length=1, max_length=MAX_DESCRIPTION)


def _domain(name: str):
    if name not in DOMAINS:
        raise HTTPException(404, f"unknown domain {name!r}; choose one of: {', '.join(DOMAINS)}")
    return get_domain(name)


def _parse(domain: str, tree: Any = None, grid: Optional[list] = None, learned: bool = True):
    """The request's tree; `learned`: whether learned tests (raw:...) may be in it (a tree a run
    handed back may hold them; a description's tree for the corpus may not)."""
    d = _domain(domain)
    vocab = d.vocab if learned else d.vocab.dictionary_only()
    try:
        if grid is not None:
            return from_grid(grid, vocab)
        if tree is None:
            raise TreeError("give a tree or a grid", "request")
        return parse_tree(tree, vocab)
    except TreeError as exc:
        words = place(exc.where, d.vocab, tree=tree, grid=grid)
        raise HTTPException(422, {"message": exc.message, "where": exc.where, "place": words,
                                  "error": f"{words}: {exc.message}"}) from exc


def _tree_view(domain: str, tree, node_confidence: Optional[dict] = None) -> dict:
    vocab = get_domain(domain).vocab
    conf = {int(k): float(v) for k, v in (node_confidence or {}).items()}
    low = {slot: "#ffcdd2" for slot, c in conf.items() if c < LOW_CONFIDENCE}
    return {"tree": tree_to_json(tree), "grid": to_grid(tree), "text": to_text(tree, vocab),
            "svg": to_svg(tree, vocab, highlight=low, notes={k: f"confidence {v:.0%}" for k, v in conf.items()}),
            "node_confidence": conf}


def changed_slots(before: list, after: list) -> list[int]:
    return [i for i in range(GRID_SLOTS) if before[i] != after[i]]


def create_app(db_path: Path, data_dir: Path, translator: Optional[Callable] = None,
               results_dir: Optional[Path] = None, max_parallel_runs: int = 1,
               allowed_hosts: Optional[tuple[str, ...]] = guards.LOOPBACK_HOSTS,
               max_waiting_runs: int = MAX_WAITING_RUNS, body_timeout: float = guards.BODY_TIMEOUT_S) -> FastAPI:
    """Build the app. `translator(domain, text)` defaults to the trained translator.
    `allowed_hosts`: the Host header values served (None: any), see `guards`. Raises
    `store.StoreError` for a database that cannot be used."""
    store = Store(db_path)
    runs = RunManager(store, max_parallel=max_parallel_runs)
    runs_dir = Path(data_dir) / "runs"
    results = results_dir or Path.cwd() / "results"
    # One translation at a time: the first one imports transformers and loads the model, which
    # is not safe to do from two threads at once (concurrent first requests failed with an
    # ImportError), and a translation takes ~20 ms, so queueing them costs nothing.
    translate_lock = threading.Lock()

    def translate(domain: str, text: str, answers: list, max_questions: int):
        if translator is not None:
            return translator(domain, text, answers=answers, max_questions=max_questions) if answers else translator(domain, text)
        from nl2policy.language.translate import translate as real

        with translate_lock:
            return real(domain, text, answers=answers, max_questions=max_questions)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        runs.start()
        yield
        runs.stop()

    app = FastAPI(title="nl2policy", version="0.1.0", lifespan=lifespan, docs_url=None, redoc_url=None,
                  description="Describe a policy in plain English, inspect and edit its tree, optimize it with PPO.")
    app.state.store, app.state.runs = store, runs
    guards.install(app, allowed_hosts, MAX_BODY_BYTES, body_timeout)

    @app.exception_handler(sqlite3.Error)
    async def database_error(request: Request, exc: sqlite3.Error) -> JSONResponse:
        return JSONResponse({"detail": f"the database {store.path} failed ({exc}); check the disk and the file, "
                                       "then restart the server"}, status_code=503)

    # --- domains ----------------------------------------------------------------------------
    @app.get("/api/domains")
    def domains() -> dict:
        # "units": how a learned test on each feature reads (trees/raw.py), for the pages' labels
        return {name: {"title": get_domain(name).title, "questions": dict(get_domain(name).vocab.questions),
                       "actions": dict(get_domain(name).vocab.actions),
                       "units": {f: dataclasses.asdict(u) for f, u in get_domain(name).vocab.features.items()}}
                for name in DOMAINS}

    @app.get("/api/briefing/{domain}")
    def briefing(domain: str) -> dict:
        _domain(domain)
        from nl2policy.data import corpus_dir

        text = (corpus_dir() / "BRIEFING.md").read_text()
        d = get_domain(domain)
        head = f"## {d.briefing_section}"
        section = text.split(head, 1)[1].split("\n## ", 1)[0] if d.briefing_section and head in text else ""
        if not section.strip():  # a domain the corpus briefing does not cover: its own dictionary
            section = "\n".join([f"The {d.title.lower()} can ask these questions:", "",
                                  *(f"- {q}" for q in d.vocab.questions.values()), "", "and do one of these:", "",
                                  *(f"- {a}" for a in d.vocab.actions.values())])
        tree_rules = text.split("## The tree", 1)[1] if "## The tree" in text else ""
        return {"domain": domain, "briefing": section.strip(), "tree_rules": tree_rules.strip()}

    # --- specify ----------------------------------------------------------------------------
    @app.post("/api/translate")
    def translate_endpoint(body: TranslateIn) -> dict:
        _domain(body.domain)
        problem = description_problem(body.description)
        if problem:
            raise HTTPException(422, {"message": problem, "where": "description"})
        try:
            result = translate(body.domain, body.description, body.answers, body.max_questions)
        except ValueError as exc:  # EmptyDescription: no words in it ("?!.,;"); a bad answer; no tree fits them
            from nl2policy.language.clarify import BadAnswer, NoTreeFits
            from nl2policy.language.translate import EmptyDescription

            if isinstance(exc, (BadAnswer, NoTreeFits)):
                raise HTTPException(422, {"message": str(exc), "where": "answers"}) from exc
            if not isinstance(exc, EmptyDescription):
                raise
            raise HTTPException(422, {"message": "the description has no words to translate: say what the robot "
                                                 "should do", "where": "description"}) from exc
        view = _tree_view(body.domain, result.tree, result.node_confidence)
        spec = store.add_spec(body.domain, body.description, view["tree"], result.confidence, list(result.warnings),
                              view["node_confidence"])
        questions = [q.to_json() for q in getattr(result, "questions", [])]
        return {"spec_id": spec["id"], "confidence": result.confidence, "warnings": list(result.warnings),
                "questions": questions, **view}

    @app.post("/api/validate")
    def validate(body: TreeIn) -> dict:
        tree = _parse(body.domain, body.tree, body.grid)
        return _tree_view(body.domain, tree)

    @app.get("/api/specs/{spec_id}")
    def get_spec(spec_id: str) -> dict:
        spec = store.get_spec(spec_id)
        if not spec:
            raise HTTPException(404, f"no specification {spec_id!r}")
        tree = parse_tree(spec["tree"], get_domain(spec["domain"]).vocab)
        return {**spec, **_tree_view(spec["domain"], tree, spec["node_confidence"])}

    @app.put("/api/specs/{spec_id}")
    def edit_spec(spec_id: str, body: TreeIn) -> dict:
        spec = store.get_spec(spec_id)
        if not spec:
            raise HTTPException(404, f"no specification {spec_id!r}")
        if body.domain != spec["domain"]:
            raise HTTPException(422, {"message": f"specification {spec_id} is for {spec['domain']}", "where": "domain"})
        tree = _parse(body.domain, body.tree, body.grid)
        old_grid, new_grid = to_grid(parse_tree(spec["tree"], get_domain(spec["domain"]).vocab)), to_grid(tree)
        kept = {k: v for k, v in spec["node_confidence"].items() if old_grid[int(k)] == new_grid[int(k)]}
        store.update_spec_tree(spec_id, tree_to_json(tree), kept)
        return get_spec(spec_id)

    # --- optimize ---------------------------------------------------------------------------
    def run_or_404(run_id: str) -> dict:
        run = store.get_run(run_id)
        if not run:
            raise HTTPException(404, f"no run {run_id!r}")
        return run

    @app.post("/api/runs", status_code=201)
    def start_run(body: RunIn) -> dict:
        tree = _parse(body.domain, body.tree)
        problem = steps_problem(body.domain, body.steps)
        if problem:
            raise HTTPException(422, {"message": problem, "where": "steps"})
        if store.count_runs(("queued",)) >= max_waiting_runs:
            raise HTTPException(429, f"{max_waiting_runs} runs are already waiting; wait for them or cancel some")
        run = store.add_run(body.domain, tree_to_json(tree), body.steps, body.seed, runs_dir, body.spec_id)
        runs.submit(run["id"])
        return run_view(run["id"])

    @app.get("/api/runs")
    def list_runs() -> list[dict]:
        return [{**run, "progress": outcome.progress(run)} for run in store.list_runs()]

    @app.get("/api/runs/{run_id}")
    def run_view(run_id: str) -> dict:
        run = run_or_404(run_id)
        out = Path(run["out_dir"])
        view: dict[str, Any] = {**run, "curve": read_curve(out, run["domain"]), "progress": outcome.progress(run)}
        vocab = get_domain(run["domain"]).vocab
        initial = parse_tree(run["tree"], vocab)
        view["initial"] = _tree_view(run["domain"], initial)
        final_path = out / "final_tree.json"
        if run["status"] == "finished" and final_path.is_file():
            final_json = json.loads(final_path.read_text())
            try:
                final = parse_tree(final_json, vocab)
                slots = changed_slots(to_grid(initial), to_grid(final))
                view["final"] = {**_tree_view(run["domain"], final), "changed": slots,
                                 "svg": to_svg(final, vocab, highlight={s: "#fff59d" for s in slots})}
            except TreeError:  # a raw threshold test the domain has no question for
                view["final"] = {"tree": final_json, "changed": [], "svg": None, "text": json.dumps(final_json, indent=1)}
            view["result"] = outcome.result(run["summary"], view["final"]["changed"])
        return view

    @app.post("/api/runs/{run_id}/resume")
    def resume_run(run_id: str) -> dict:
        run = run_or_404(run_id)
        if run["status"] == "failed":
            raise HTTPException(409, f"run {run_id} failed ({run['error']}); resuming would fail the same way: "
                                     "start a new run")
        if run["status"] not in ("interrupted", "cancelled"):
            raise HTTPException(409, f"run {run_id} is {run['status']}; only interrupted or cancelled runs resume")
        pid = holder(Path(run["out_dir"]))
        if pid is not None:
            raise HTTPException(409, f"process {pid} is still writing run {run_id}; wait for it to end")
        runs.submit(run_id)
        return run_view(run_id)

    @app.post("/api/runs/{run_id}/cancel")
    def cancel_run(run_id: str) -> dict:
        """Stop a queued or running run; it keeps its last checkpoint and can be resumed."""
        run = run_or_404(run_id)
        if not runs.cancel(run_id):
            raise HTTPException(409, f"run {run_id} is {run['status']}; only queued or running runs can be cancelled")
        return run_view(run_id)

    @app.delete("/api/runs/{run_id}")
    def delete_run(run_id: str) -> dict:
        """Forget a run that is not going, and delete its folder."""
        run = run_or_404(run_id)
        if run["status"] in WAITING:
            raise HTTPException(409, f"run {run_id} is {run['status']}; cancel it first")
        out = Path(run["out_dir"])
        if holder(out) is not None:
            raise HTTPException(409, f"a process is still writing run {run_id}; wait for it to end")
        store.delete_run(run_id)
        if out.resolve().parent == runs_dir.resolve() and out.is_dir():
            shutil.rmtree(out, ignore_errors=True)
        return {"deleted": run_id}

    @app.get("/api/runs/{run_id}/policy")
    def download_policy(run_id: str) -> Response:
        view = run_view(run_id)
        if "final" not in view:
            raise HTTPException(409, f"run {run_id} has not finished")
        body = {"domain": view["domain"], "initial_tree": view["initial"]["tree"], "final_tree": view["final"]["tree"],
                "summary": view["summary"]}
        return JSONResponse(body, headers={"Content-Disposition": f'attachment; filename="policy-{run_id}.json"'})

    @app.get("/api/baselines/{domain}")
    def baselines(domain: str) -> dict:
        _domain(domain)
        return baseline_curves(results, domain)

    # --- collect ----------------------------------------------------------------------------
    @app.post("/api/submissions", status_code=201)
    def submit(body: SubmissionIn) -> dict:
        tree = _parse(body.domain, grid=body.grid, learned=False)
        if not has_visible(body.writer):
            raise HTTPException(422, {"message": "give your name or a nickname (it has no visible characters)", "where": "writer"})
        if not has_visible(body.description):
            raise HTTPException(422, {"message": "describe your tree in words before submitting", "where": "description"})
        return store.add_submission(body.domain, body.writer.strip(), tree_to_json(tree), body.description.strip())

    @app.get("/api/submissions")
    def submissions(domain: Optional[str] = None) -> list[dict]:
        if domain:
            _domain(domain)
        return store.list_submissions(domain)

    # --- pages ------------------------------------------------------------------------------
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/docs", include_in_schema=False)
    def api_reference() -> FileResponse:
        """The API reference, drawn from /openapi.json by a page served here: it works offline
        (FastAPI's Swagger UI loads its scripts from a CDN; it stays at /docs/swagger)."""
        return FileResponse(STATIC / "docs.html")

    @app.get("/docs/swagger", include_in_schema=False)
    def swagger() -> HTMLResponse:
        return get_swagger_ui_html(openapi_url="/openapi.json", title="nl2policy API (Swagger UI, needs internet)")

    @app.get("/favicon.ico", include_in_schema=False)
    def favicon() -> FileResponse:
        return FileResponse(STATIC / "favicon.svg", media_type="image/svg+xml")

    @app.get("/", include_in_schema=False)
    def specify_page() -> FileResponse:
        return FileResponse(STATIC / "specify.html")

    @app.get("/optimize", include_in_schema=False)
    def optimize_page() -> FileResponse:
        return FileResponse(STATIC / "optimize.html")

    @app.get("/collect", include_in_schema=False)
    def collect_page() -> FileResponse:
        return FileResponse(STATIC / "collect.html")

    return app
