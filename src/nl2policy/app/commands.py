"""App commands: ``serve``, ``export-submissions``, and ``run`` (the end-to-end main job)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer


def register(app: typer.Typer) -> None:
    @app.command()
    def serve(
        host: str = typer.Option("127.0.0.1"),
        port: int = typer.Option(8000),
        db: Optional[Path] = typer.Option(None, help="SQLite file (default: <data dir>/nl2policy.sqlite)"),
        data_dir: Optional[Path] = typer.Option(None, help="Folder for runs (default: $NL2POLICY_HOME or the user data dir)"),
        results: Path = typer.Option(Path("results"), help="Folder with the baseline learning curves"),
    ) -> None:
        """Start the web app: Specify, Optimize and Collect pages, and the JSON API (/docs)."""
        import uvicorn

        from nl2policy.app.server import create_app
        from nl2policy.paths import home

        base = data_dir or home()
        application = create_app(db or base / "nl2policy.sqlite", base, results_dir=results)
        typer.echo(f"nl2policy app on http://{host}:{port}/  (API schema: http://{host}:{port}/docs)")
        uvicorn.run(application, host=host, port=port, log_level="warning")

    @app.command("export-submissions")
    def export_submissions(
        domain: str = typer.Option(..., help="taxi or highway"),
        out: Path = typer.Option(..., help="JSONL file to write, in the corpus format"),
        db: Optional[Path] = typer.Option(None, help="SQLite file (default: <data dir>/nl2policy.sqlite)"),
    ) -> None:
        """Write the Collect page's submissions for a domain as corpus JSONL."""
        from nl2policy.app.store import Store
        from nl2policy.cli import domain_or_fail
        from nl2policy.paths import home

        domain_or_fail(domain)
        rows = Store(db or home() / "nl2policy.sqlite").list_submissions(domain)
        with out.open("w") as fh:
            for row in rows:
                fh.write(json.dumps({"id": f"collected-{row['id']}", "domain": row["domain"], "writer": row["writer"],
                                     "tree": row["tree"], "description": row["description"]}) + "\n")
        typer.echo(f"wrote {len(rows)} {domain} specifications to {out}")
