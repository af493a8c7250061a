"""``HEAD`` on every ``GET`` route (download tools probe a file's size and range support with it).

Starlette adds ``HEAD`` to its own GET routes; FastAPI's do not, so a ``HEAD`` was a 405 everywhere. This
middleware answers a ``HEAD`` as the ``GET`` of the same URL up to its headers (status, ``Content-Length``,
``Content-Range``, ``Accept-Ranges``, errors alike), then ends the response without a body and tells the
app the client is gone: a file download stops before reading the file, an event stream ends at once.
The OpenAPI document is unchanged (one operation per route, as before).
"""

from __future__ import annotations

from starlette.types import ASGIApp, Message, Receive, Scope, Send


class HeadMiddleware:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "HEAD":
            await self.app(scope, receive, send)
            return
        done = False

        async def send_head(message: Message) -> None:
            nonlocal done
            if done:
                return
            if message["type"] == "http.response.body":
                done = True
                message = {"type": "http.response.body", "body": b"", "more_body": False}
            await send(message)

        async def receive_until_done() -> Message:
            if done:
                return {"type": "http.disconnect"}
            return await receive()

        await self.app({**scope, "method": "GET"}, receive_until_done, send_head)
