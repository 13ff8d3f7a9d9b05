"""The sign-in API the page uses (http_guard.py has already checked Origin, the request
header and, but for sign-in, the cookie):

    POST /api/sign-in   {"token": "..."}  -> 200 {"name", "role", "idle_s", "max_age_s"}
                                             and the sign-in cookie; 401 {"error"} if refused
    POST /api/sign-out                    -> 204; the cookie cleared, the person's pages closed
    GET  /api/me                          -> 200 {"name", "role", ...}; 401 when not signed in
"""
from __future__ import annotations

import asyncio
import json

from aiohttp import web

from landscape.supervisor.connections import HEADER_TIMEOUT_S
from landscape.supervisor.http_guard import (GUARD, SIGN_IN_COOKIE, SIGN_IN_PATH, SIGN_INS,
                                             signed_in)
from landscape.supervisor.sign_in import SignIn, SignInRefused

MAX_BODY = 4096   # bytes of a sign-in request's body


def add_routes(app: web.Application) -> None:
    app.router.add_post(SIGN_IN_PATH, _sign_in)
    app.router.add_post("/api/sign-out", _sign_out)
    app.router.add_get("/api/me", _me)


def _describe(record: SignIn, sign_ins) -> dict:
    return {"name": record.name, "role": record.role_label, "idle_s": sign_ins.idle_s,
            "max_age_s": sign_ins.max_age_s}


async def _token_of(request: web.Request) -> str:
    if request.content_type != "application/json":
        raise web.HTTPUnsupportedMediaType(text="send the token as JSON: {\"token\": \"...\"}")
    if (request.content_length or 0) > MAX_BODY:
        raise web.HTTPRequestEntityTooLarge(max_size=MAX_BODY, actual_size=request.content_length)
    try:   # the body is read under the header's bound: a slow one is dropped too
        async with asyncio.timeout(HEADER_TIMEOUT_S):
            body = await request.content.read(MAX_BODY + 1)
    except TimeoutError:
        raise web.HTTPRequestTimeout(text="the request's body did not arrive in time") from None
    if len(body) > MAX_BODY:
        raise web.HTTPRequestEntityTooLarge(max_size=MAX_BODY, actual_size=len(body))
    try:
        token = json.loads(body).get("token")
    except (ValueError, AttributeError):
        token = None
    if not isinstance(token, str) or not token.strip():
        raise web.HTTPBadRequest(text="send the token as JSON: {\"token\": \"...\"}")
    return token.strip()


async def _sign_in(request: web.Request) -> web.Response:
    token = await _token_of(request)
    sign_ins = request.app[SIGN_INS]
    try:
        record = sign_ins.sign_in(token, request.remote or "?")
    except SignInRefused as refusal:
        return web.json_response({"error": str(refusal)}, status=401)
    request.app[GUARD].vouch(request.protocol)   # this connection has shown who it is
    response = web.json_response(_describe(record, sign_ins))
    response.set_cookie(SIGN_IN_COOKIE, record.id, httponly=True, samesite="Strict",
                        secure=request.secure, path="/", max_age=round(sign_ins.max_age_s))
    return response


async def _sign_out(request: web.Request) -> web.Response:
    request.app[SIGN_INS].sign_out(signed_in(request))
    response = web.Response(status=204)
    response.del_cookie(SIGN_IN_COOKIE, path="/")
    return response


async def _me(request: web.Request) -> web.Response:
    return web.json_response(_describe(signed_in(request), request.app[SIGN_INS]))
