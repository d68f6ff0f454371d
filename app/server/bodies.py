"""JSON bodies read strictly, in one place for every route: what ``json.loads`` would take
silently or fail on without naming a field is a 422 naming the field (or "body") and why.

An ASGI middleware inside RequestLimits (the token and the size are checked first): a
request that may carry a body (POST, PUT, PATCH, DELETE; never ``/api/estop``, which reads
none and must not wait on this) with a JSON content type (``application/json``,
``application/*+json``: the bodies FastAPI parses as JSON) and a non-empty body is parsed
here before the route sees it. Refused (422, app/server/errors.py ``invalid_body``):

- a UTF-8 byte order mark at the start (RFC 8259 section 8.1: senders must not add one;
  ``json.loads`` of bytes would skip it);
- bytes that are not UTF-8 (FastAPI answered an undocumented 400 naming nothing);
- an object with the same key twice (``json.loads`` keeps the last one, silently);
- an integer longer than Python's int-to-string limit (``sys.get_int_max_str_digits()``,
  4300 digits: a ValueError, a 400 before), naming its field;
- nesting deeper than the parser can go (a RecursionError, a 400 before);
- text that is not JSON, with its line and column.

A body that passes is handed on unchanged and parsed again by the route (at most
``server.max_body_bytes``, 1 MiB: milliseconds).
"""

from __future__ import annotations

import json
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.server.errors import invalid_body

WITH_BODY = frozenset({"POST", "PUT", "PATCH", "DELETE"})
UNPARSED = frozenset({"/api/estop"})  # the e-stop reads no body: never delayed by one
BOM = b"\xef\xbb\xbf"


class BodyError(ValueError):
    """A JSON body that cannot be read: ``field`` (dotted, ``"body"`` for the whole body)
    and ``reason``; ``str()`` reads ``field: reason``."""

    def __init__(self, field: str, reason: str) -> None:
        self.field, self.reason = field, reason
        super().__init__(f"{field}: {reason}")


class _Problem:
    """Left in the parsed tree where a value could not be read, so its path can be named."""

    def __init__(self, reason: str) -> None:
        self.reason = reason


def loads_strict(raw: bytes) -> Any:
    """The JSON value of ``raw`` (UTF-8 bytes, no BOM, each key once per object).

    Raises BodyError naming the field and the reason (see the module doc). Costs as
    ``json.loads`` with an ``object_pairs_hook`` when the body is good; the tree is walked
    for the field's path only when something was found."""
    if raw.startswith(BOM):
        raise BodyError("body", "starts with a UTF-8 byte order mark (BOM): send JSON without it")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BodyError("body", f"not UTF-8 (byte {exc.start}: {exc.reason})") from None
    found = False

    def pairs(items: list[tuple[str, Any]]) -> Any:
        nonlocal found
        result: dict[str, Any] = {}
        for key, value in items:
            if key in result:
                found = True
                return {key: _Problem(f"duplicate key {key!r}: each key may appear once")}
            result[key] = value
        return result

    def integer(digits: str) -> Any:
        nonlocal found
        try:
            return int(digits)
        except ValueError:  # past sys.get_int_max_str_digits()
            found = True
            return _Problem(f"integer of {len(digits.lstrip('-'))} digits: too long to read")

    try:
        value = json.loads(text, object_pairs_hook=pairs, parse_int=integer)
    except RecursionError:
        raise BodyError("body", "JSON nested too deeply to read") from None
    except json.JSONDecodeError as exc:
        where = f"line {exc.lineno} column {exc.colno}"
        raise BodyError("body", f"not valid JSON: {exc.msg} at {where}") from None
    if found:
        _raise_first_problem(value)
    return value


def _raise_first_problem(value: Any) -> None:
    """BodyError at the first _Problem in ``value``'s tree (no recursion: any depth)."""
    stack: list[tuple[tuple[str, ...], Any]] = [((), value)]
    while stack:
        path, node = stack.pop()
        if isinstance(node, _Problem):
            raise BodyError(".".join(path) or "body", node.reason)
        if isinstance(node, dict):
            children = [((*path, str(k)), v) for k, v in node.items()]
        elif isinstance(node, list):
            children = [((*path, str(i)), v) for i, v in enumerate(node)]
        else:
            continue
        stack.extend(reversed(children))  # in document order


def is_json(scope: Scope) -> bool:
    """A JSON content type, as FastAPI decides to parse a body as JSON."""
    for name, value in scope["headers"]:
        if name == b"content-type":
            kind = value.decode("latin-1").split(";", 1)[0].strip().lower()
            main, _, sub = kind.partition("/")
            return main == "application" and (sub == "json" or sub.endswith("+json"))
    return False


class StrictJSON:
    """ASGI middleware: a JSON body is read by ``loads_strict`` before the route sees it
    (see the module doc); refused with a 422 naming the field and the reason."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http"
            or scope["path"] in UNPARSED
            or scope["method"] not in WITH_BODY
            or not is_json(scope)
        ):
            await self.app(scope, receive, send)
            return
        chunks: list[bytes] = []
        while True:
            message = await receive()
            if message["type"] != "http.request":  # the client left: the app sees it so
                await self.app(scope, _replay([message], receive), send)
                return
            chunks.append(message.get("body", b""))
            if not message.get("more_body", False):
                break
        raw = b"".join(chunks)
        if raw:
            try:
                loads_strict(raw)
            except BodyError as exc:
                await invalid_body(scope["path"], [(exc.field, exc.reason)])(scope, receive, send)
                return
        whole: Message = {"type": "http.request", "body": raw, "more_body": False}
        await self.app(scope, _replay([whole], receive), send)


def _replay(messages: list[Message], receive: Receive) -> Receive:
    """``messages`` once, then the client's own receive (a later disconnect still shows)."""
    pending = list(reversed(messages))

    async def replayed() -> Message:
        return pending.pop() if pending else await receive()

    return replayed
