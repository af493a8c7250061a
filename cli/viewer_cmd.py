"""`vtdslam viewer`: the 3D viewer hub (one viser scene per opened run)."""
from __future__ import annotations

from typing import Annotated, Optional

import typer


def register(app: typer.Typer) -> None:
    app.command("viewer")(viewer_command)


def viewer_command(
    host: Annotated[Optional[str], typer.Option(help="Bind address (default VTD_HOST).")] = None,
    port: Annotated[Optional[int], typer.Option(help="Control port (default VTD_VIEWER_PORT, 8080).")] = None,
) -> None:
    """Serve runs' maps and trajectories in viser; the dashboard asks it for a run's scene."""
    import logging

    from storage.artifacts import ArtifactStore
    from storage.settings import get_settings
    from webui.viewer.hub import HubConfig, ViewerHub, serve_hub

    logging.basicConfig(level=logging.INFO, format="%(asctime)s viewer %(levelname)s %(message)s")
    settings = get_settings()
    hub = ViewerHub(ArtifactStore(settings.data_dir),
                    HubConfig(host=host or settings.host, port=port or settings.viewer_port))
    try:
        serve_hub(hub)
    except KeyboardInterrupt:
        pass
