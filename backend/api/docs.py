"""``/docs`` (Swagger UI) and ``/redoc`` from assets the api serves itself, so they render offline.

FastAPI's defaults load Swagger UI and ReDoc from a CDN: without internet the page stayed blank
("SwaggerUIBundle is not defined"). The scripts come from the pinned PyPI package ``fastapi-offline``
(MIT; Swagger UI is Apache-2.0, ReDoc MIT, licence notes in the scripts' headers), served under
``/docs-static``; we use only its static files, not its FastAPI subclass. ReDoc's one remaining outside
request, the credit logo in its sidebar, is pointed at an empty inline image (the credit text stays).
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

ASSETS_URL = "/docs-static"
REDOC_CREDIT_LOGO = b"https://cdn.redoc.ly/redoc/logo-mini.svg"
EMPTY_IMAGE = b"data:image/svg+xml,%3Csvg xmlns='http://www.w3.org/2000/svg'/%3E"


def assets_dir() -> Path:
    """The folder of ``swagger-ui-bundle.js``, ``swagger-ui.css``, ``redoc.standalone.js``, ``favicon.png``."""
    return Path(str(files("fastapi_offline") / "static"))


def include_docs(app: FastAPI) -> None:
    """Add ``/docs``, ``/redoc`` and their assets; the app must be built with ``docs_url=None, redoc_url=None``."""
    openapi_url = app.openapi_url or "/openapi.json"
    title = f"{app.title} API"
    redoc_js = (assets_dir() / "redoc.standalone.js").read_bytes().replace(REDOC_CREDIT_LOGO, EMPTY_IMAGE)

    @app.get(f"{ASSETS_URL}/redoc.standalone.js", include_in_schema=False)  # before the mount, which it shadows
    def redoc_script() -> Response:
        return Response(redoc_js, media_type="text/javascript", headers={"Cache-Control": "public, max-age=86400"})

    app.mount(ASSETS_URL, StaticFiles(directory=assets_dir()), name="docs-static")

    @app.get("/docs", include_in_schema=False)
    def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=openapi_url,
            title=title,
            swagger_js_url=f"{ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{ASSETS_URL}/swagger-ui.css",
            swagger_favicon_url=f"{ASSETS_URL}/favicon.png",
        )

    @app.get("/redoc", include_in_schema=False)
    def redoc() -> HTMLResponse:
        return get_redoc_html(
            openapi_url=openapi_url,
            title=title,
            redoc_js_url=f"{ASSETS_URL}/redoc.standalone.js",
            redoc_favicon_url=f"{ASSETS_URL}/favicon.png",
            with_google_fonts=False,  # fonts from Google would fail offline; the system fonts are fine
        )
