"""`vtdslam viewer`: the 3D viewer hub (one viser scene per opened run)."""
from __future__ import annotations

from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("viewer")(viewer_command)


def viewer_command(
    host: Annotated[str | None, typer.Option(help="Bind address (default VTD_HOST).")] = None,
    port: Annotated[int | None, typer.Option(help="Control port (default VTD_VIEWER_PORT, 8080).")] = None,
) -> None:
    """Serve runs' maps and trajectories in viser; the api asks it for a run's scene and proxies it.

    With VTD_API_TOKEN set, only the api (which sends a key derived from the token) may open runs, and the
    per-run viser servers bind loopback.
    """
    import logging

    from storage.artifacts import ArtifactStore
    from storage.settings import get_settings
    from webui.viewer.hub import HubConfig, ViewerHub, serve_hub

    logging.basicConfig(level=logging.INFO, format="%(asctime)s viewer %(levelname)s %(message)s")
    settings = get_settings()
    hub = ViewerHub(ArtifactStore(settings.data_dir),
                    HubConfig(host=host or settings.host, port=port or settings.viewer_port,
                              key=settings.viewer_hub_key))
    try:
        serve_hub(hub)
    except KeyboardInterrupt:
        pass
