"""``/docs`` and ``/redoc`` load their scripts from the api itself (offline), never from a CDN."""
from __future__ import annotations

import re

import pytest

ASSET = re.compile(r"""(?:src|href)=["']([^"']+)["']""")


@pytest.mark.parametrize(("page", "script"), [("/docs", "swagger-ui-bundle.js"), ("/redoc", "redoc.standalone.js")])
def test_doc_pages_use_only_local_assets(client, page, script):
    r = client.get(page)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    urls = ASSET.findall(r.text)
    assert f"/docs-static/{script}" in urls
    assert all(u.startswith("/") and not u.startswith("//") for u in urls), urls  # nothing off this origin
    assert "googleapis" not in r.text and "cdn." not in r.text


@pytest.mark.parametrize("name", ["swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js"])
def test_doc_assets_are_served(client, name):
    r = client.get(f"/docs-static/{name}")
    assert r.status_code == 200 and len(r.content) > 10_000
    kind = "css" if name.endswith(".css") else "javascript"
    assert kind in r.headers["content-type"]


def test_redoc_script_makes_no_outside_request(client):
    script = client.get("/docs-static/redoc.standalone.js").text
    assert "cdn.redoc.ly" not in script and "Redoc" in script
