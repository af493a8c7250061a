"""`vtdslam serve`: the embedded default on one machine — api, one worker and the viewer, stopped together."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Mapping
from typing import Annotated

import typer

STOP_TIMEOUT_S = 30


def register(app: typer.Typer) -> None:
    app.command("serve")(serve_command)


def serve_command(
    host: Annotated[str | None, typer.Option(
        help="Bind address of every server started: api, viewer hub, run viewers (default VTD_HOST, 127.0.0.1)."
    )] = None,
    port: Annotated[int | None, typer.Option(help="Port (default from VTD_PORT, 8000).")] = None,
    worker: Annotated[bool, typer.Option("--worker/--no-worker", help="Also start one worker process.")] = True,
    viewer: Annotated[bool, typer.Option("--viewer/--no-viewer", help="Also start the 3D viewer hub.")] = True,
) -> None:
    """Start the service: the api, one worker and the 3D viewer; Ctrl-C stops them all cleanly.

    Each runs as its own process (see `vtdslam worker`, `vtdslam viewer`); if one exits, the others stop.
    Browsers need the api's port only: the 3D viewer is proxied under the api's ``/viewer/``.
    """
    from storage.db import init_db
    from storage.settings import get_settings

    settings = get_settings(**{k: v for k, v in (("host", host), ("port", port)) if v is not None})
    # One setting for every process: the children read VTD_HOST/VTD_PORT (the api dials the hub with them).
    env = {**os.environ, "VTD_HOST": settings.host, "VTD_PORT": str(settings.port)}
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    init_db(settings)  # once, before the processes start (they would each migrate otherwise)
    # name -> (command, the signal that stops it cleanly)
    commands = {
        # uvicorn with the api's header size and time limits (cli/api_server.py); host and port from env
        "api": ([sys.executable, "-m", "cli.api_server"], signal.SIGTERM),
    }
    if worker:
        commands["worker"] = ([sys.executable, "-m", "cli.main", "worker"], signal.SIGTERM)
    if viewer:
        commands["viewer"] = ([sys.executable, "-m", "cli.main", "viewer"], signal.SIGINT)
    raise typer.Exit(supervise(commands, env))


def _die_with_parent() -> None:  # runs in the child before exec (Linux): no orphans if serve is killed
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def supervise(commands: Mapping[str, tuple[list[str], int]], env: Mapping[str, str] | None = None) -> int:
    """Run the processes until a signal comes or one exits; then stop the others (their stop signal,
    then SIGKILL after ``STOP_TIMEOUT_S``).

    Children get their own session, so a terminal's Ctrl-C reaches only this process, which sends each
    child its stop signal once (a second Ctrl-C would make them abort instead of finishing cleanly).
    """
    procs: dict[str, subprocess.Popen[bytes]] = {}
    stop: dict[str, int | None] = {"signal": None}

    def on_signal(signum: int, _frame: object) -> None:
        stop["signal"] = signum

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    code = 0
    try:
        for name, (cmd, _sig) in commands.items():
            procs[name] = subprocess.Popen(cmd, env=env, start_new_session=True, preexec_fn=_die_with_parent)
            typer.echo(f"started {name} (pid {procs[name].pid})", err=True)
        while stop["signal"] is None:
            exited = [(n, p.returncode) for n, p in procs.items() if p.poll() is not None]
            if exited:
                name, code = exited[0]
                typer.echo(f"{name} exited with code {code}; stopping the others", err=True)
                code = code or 1
                break
            time.sleep(0.2)
    finally:
        for name, p in procs.items():
            if p.poll() is None:
                p.send_signal(commands[name][1])
        deadline = time.monotonic() + STOP_TIMEOUT_S
        for name, p in procs.items():
            try:
                p.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                typer.echo(f"{name} did not stop in {STOP_TIMEOUT_S} s; killing it", err=True)
                p.kill()
                p.wait()
        for s, handler in old.items():
            signal.signal(s, handler)
    if stop["signal"] is not None:
        typer.echo("stopped", err=True)
        return 0
    return code
