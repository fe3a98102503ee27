"""App commands: ``serve`` and ``export-submissions``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer


def _port_free_or_fail(host: str, port: int) -> None:
    """Say in one line that the address is taken (or wrong) before anything starts; uvicorn
    would log it and exit with code 3."""
    import socket

    from nl2policy.console import fail

    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        fail(f"--host {host} is not an address this machine can listen on ({exc.strerror})")
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn binds
        try:
            probe.bind(address)
        except OSError as exc:
            fail(f"cannot listen on {host}:{port}: {exc.strerror or exc}; is another server running there? "
                 "choose another --port")


def register(app: typer.Typer) -> None:
    @app.command()
    def serve(
        host: str = typer.Option("127.0.0.1", help="Address to listen on; anything but loopback lets other machines in"),
        port: int = typer.Option(8000, help="TCP port, 1 to 65535"),
        db: Optional[Path] = typer.Option(None, help="SQLite file (default: <data dir>/nl2policy.sqlite)"),
        data_dir: Optional[Path] = typer.Option(None, help="Folder for runs (default: $NL2POLICY_HOME or the user data dir)"),
        results: Path = typer.Option(Path("results"), help="Folder with the baseline learning curves"),
        allow_host: Optional[list[str]] = typer.Option(None, help="Another host name the pages may be reached by "
                                                                  "(repeatable); others are refused, against DNS rebinding"),
    ) -> None:
        """Start the web app: Specify, Optimize and Collect pages, and the JSON API (/docs)."""
        from nl2policy.app.guards import allowed_hosts_for, is_loopback
        from nl2policy.console import err, fail, home_or_fail, out_dir_or_fail, store_or_fail

        if not 1 <= port <= 65535:
            fail(f"--port must be from 1 to 65535, not {port}")
        _port_free_or_fail(host, port)
        base = out_dir_or_fail(data_dir, "--data-dir") if data_dir else home_or_fail()
        db_path = db or base / "nl2policy.sqlite"
        store_or_fail(db_path)  # a damaged or unwritable database: one line naming it, before anything starts
        import uvicorn

        from nl2policy.app.server import create_app

        allowed = allowed_hosts_for(host, allow_host or ())
        if not is_loopback(host):
            err.print(f"[yellow]warning:[/] listening on {host}: other machines on the network can reach the app, "
                      "read its specifications and start runs; it has no login", highlight=False)
        application = create_app(db_path, base, results_dir=results, allowed_hosts=allowed)
        shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
        typer.echo(f"nl2policy app on http://{shown}:{port}/  (API reference: http://{shown}:{port}/docs)")
        uvicorn.run(application, host=host, port=port, log_level="warning")

    @app.command("export-submissions")
    def export_submissions(
        domain: str = typer.Option(..., help="taxi or highway"),
        out: Path = typer.Option(..., help="JSONL file to write, in the corpus format"),
        db: Optional[Path] = typer.Option(None, help="SQLite file (default: <data dir>/nl2policy.sqlite)"),
    ) -> None:
        """Write the Collect page's submissions for a domain as corpus JSONL."""
        from nl2policy.console import domain_or_fail, fail, home_or_fail, out_file_or_fail, store_or_fail

        domain_or_fail(domain)
        out_file_or_fail(out)
        rows = store_or_fail(db or home_or_fail() / "nl2policy.sqlite").list_submissions(domain)
        try:
            with out.open("w") as fh:
                for row in rows:
                    fh.write(json.dumps({"id": f"collected-{row['id']}", "domain": row["domain"], "writer": row["writer"],
                                         "tree": row["tree"], "description": row["description"]}) + "\n")
        except OSError as exc:
            fail(f"cannot write --out {out}: {exc.strerror or exc}")
        typer.echo(f"wrote {len(rows)} {domain} specifications to {out}")
