"""What a request must show before any handler of the supervisor runs.

- Origin: a request that carries an Origin header must come from one of the supervisor's
  origins (origins.py), or it is refused (403). The WebSocket handshake and every request
  that is not a GET or HEAD must carry one (browsers always send it there): a handshake from
  another origin is refused before the upgrade.
- Cross-site requests: besides the Origin, every state-changing request (POST: sign-in,
  sign-out) must carry the header `X-Landscape-Request: page`, which a form cannot send and
  a fetch from another origin cannot send without a CORS preflight that the supervisor
  never grants; the sign-in cookie is SameSite=Strict. (SameSite alone would not do: a
  page on another port of the same host is the same site.)
- Sign-in: the WebSocket and the API (but the sign-in itself) need a valid sign-in cookie
  (401 without). The built page is public: it shows the sign-in form.
"""
from __future__ import annotations

from aiohttp import web

from landscape.supervisor.connections import ConnectionGuard
from landscape.supervisor.origins import OriginPolicy
from landscape.supervisor.sign_in import SignIn, SignIns

SIGN_IN_COOKIE = "landscape_sign_in"
REQUEST_HEADER, REQUEST_HEADER_VALUE = "X-Landscape-Request", "page"
WS_PATH = "/ws"
API_PREFIX = "/api/"
SIGN_IN_PATH = "/api/sign-in"
READS = ("GET", "HEAD")

POLICY = web.AppKey("origin_policy", OriginPolicy)
SIGN_INS = web.AppKey("sign_ins", SignIns)
GUARD = web.AppKey("connection_guard", ConnectionGuard)
SIGNED_IN = web.RequestKey("signed_in", SignIn)   # the SignIn of a request that needs one


def refused(status: type[web.HTTPException], reason: str) -> web.HTTPException:
    """The refusal, on a connection closed after it: a refused client holds nothing."""
    refusal = status(text=reason, content_type="text/plain")
    refusal.force_close()
    return refusal


@web.middleware
async def guard(request: web.Request, handler):
    origin = request.headers.get("Origin")
    changing = request.method not in READS
    if origin is not None and not request.app[POLICY].allows(origin):
        raise refused(web.HTTPForbidden, f"requests from {origin} are refused: the supervisor "
                                         f"serves its own origin (and [supervisor] "
                                         f"allowed_origins)")
    if origin is None and (changing or request.path == WS_PATH):
        raise refused(web.HTTPForbidden, "this request must come from the supervisor's page "
                                         "(it carries no Origin header)")
    if changing and request.headers.get(REQUEST_HEADER) != REQUEST_HEADER_VALUE:
        raise refused(web.HTTPForbidden, f"a state-changing request must carry "
                                         f"{REQUEST_HEADER}: {REQUEST_HEADER_VALUE}")
    if request.path == WS_PATH or (request.path.startswith(API_PREFIX)
                                   and request.path != SIGN_IN_PATH):
        sign_in = request.app[SIGN_INS].find(request.cookies.get(SIGN_IN_COOKIE))
        if sign_in is None:
            raise refused(web.HTTPUnauthorized, "sign in first")
        request[SIGNED_IN] = sign_in
        request.app[GUARD].vouch(request.protocol)
    return await handler(request)


def signed_in(request: web.Request) -> SignIn:
    """The sign-in `guard` found for this request."""
    return request[SIGNED_IN]
