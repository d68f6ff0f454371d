"""Which web pages may talk to the server: the Host and Origin checks.

A browser lets any page it shows send requests to 127.0.0.1, and a WebSocket has no
same-origin rule at all. Two attacks follow, and two checks close them (the checks Jupyter
and Django make; Starlette's ``TrustedHostMiddleware`` is the first):

- **DNS rebinding.** A page on ``rebind.evil.example`` makes its own name resolve to
  127.0.0.1 and then calls the server as its own origin: the browser sends
  ``Host: rebind.evil.example:8000``. So the ``Host`` header must name this machine: a
  loopback name (``localhost``, ``*.localhost``), an IP address literal (a rebinding
  needs a name; a page can only send an address it was itself loaded from), the configured
  ``[server] host``, or one of ``[server] allowed_hosts`` (``"*"``: any, for a proxy that
  checks it).
- **Cross-site requests.** A page of another origin calls the API or opens a WebSocket:
  the browser sends its ``Origin``. So a request that carries an ``Origin`` must come from
  the server's own origin (the scheme, host and port of its ``Host`` header: the dashboard
  calling its own port, the 3D scene its own), or from one of ``[server] allowed_origins``.
  Requests with no ``Origin`` (curl, scripts, a browser's own navigation) pass.

The HTTP port (app/server/origins.py), the 3D scene's port (app/scene/origins.py) and the
e-stop listener ask the same :class:`OriginPolicy`.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

LOOPBACK_NAMES = ("localhost",)
DEFAULT_PORTS = {"http": 80, "https": 443, "ws": 80, "wss": 443}


def split_host(host: str) -> tuple[str, int | None] | None:
    """A ``Host`` header's (name, port): lower case, no trailing dot, IPv6 without brackets;
    None when it is not a host (empty, a bad port, stray brackets)."""
    host = host.strip().lower()
    if not host:
        return None
    if host.startswith("["):
        name, sep, rest = host[1:].partition("]")
        if not sep or (rest and not rest.startswith(":")):
            return None
        port_text = rest[1:] if rest else None
    else:
        name, sep, port_text = host.rpartition(":") if host.count(":") == 1 else (host, "", "")
        if not sep:
            port_text = None
    if port_text is not None:
        if not port_text.isdigit() or not 0 < int(port_text) < 65536:
            return None
        port = int(port_text)
    else:
        port = None
    name = name.rstrip(".")
    return (name, port) if name else None


def _is_address(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


@dataclass(frozen=True)
class OriginPolicy:
    """The Host and Origin rule (see the module docstring).

    allowed_hosts: host names accepted besides loopback names and address literals
    (lower case; ``"*"``: any); allowed_origins: origins (``scheme://host[:port]``)
    accepted besides the server's own.
    """

    allowed_hosts: tuple[str, ...] = ()
    allowed_origins: tuple[str, ...] = ()

    @classmethod
    def from_settings(cls, server: Any) -> OriginPolicy:
        """The policy of a ``[server]`` section (``ServerSettings``; a missing key: none)."""
        hosts = [str(h).lower().rstrip(".") for h in getattr(server, "allowed_hosts", ())]
        host = str(getattr(server, "host", "") or "").lower()
        if host and host not in ("0.0.0.0", "::") and not _is_address(host.strip("[]")):
            hosts.append(host)  # the name it was told to bind
        origins = tuple(_normal_origin(o) or o for o in getattr(server, "allowed_origins", ()))
        return cls(tuple(hosts), origins)

    def host_ok(self, name: str) -> bool:
        """Is ``name`` (from :func:`split_host`) this machine's?"""
        if "*" in self.allowed_hosts or _is_address(name):
            return True
        if name in LOOPBACK_NAMES or name.endswith(".localhost"):
            return True
        return name in self.allowed_hosts

    def refusal(self, host: str | None, origin: str | None) -> str | None:
        """Why a request with these ``Host`` and ``Origin`` headers is refused, or None.

        host: the Host header (None: missing, refused); origin: the Origin header (None:
        none sent, fine).
        """
        parsed = split_host(host or "")
        if parsed is None:
            return f"Host header {host!r} is not a host name"
        name, port = parsed
        if not self.host_ok(name):
            return (
                f"Host {name!r} is not this machine (a DNS rebinding page?): use 127.0.0.1 "
                "or localhost, or add the name to [server] allowed_hosts"
            )
        if origin is None:
            return None
        normal = _normal_origin(origin)
        if normal is None:
            return f"Origin {origin!r} is not a web origin"
        if normal in self.allowed_origins:
            return None
        # the scheme is not compared: behind a TLS proxy the page is https, the hop http
        scheme, origin_name, origin_port = _origin_parts(normal)
        own_port = port if port is not None else DEFAULT_PORTS.get(scheme)
        if origin_name == name and origin_port == own_port:
            return None
        return (
            f"Origin {origin!r} is another site: only the server's own pages may use it "
            "(or add the origin to [server] allowed_origins)"
        )

    def refusal_of_headers(self, headers: Iterable[tuple[bytes, bytes]]) -> str | None:
        """:meth:`refusal` for ASGI-style raw headers (a second Host or Origin: refused)."""
        seen: dict[bytes, list[str]] = {b"host": [], b"origin": []}
        for key, value in headers:
            key = key.lower()
            if key in seen:
                seen[key].append(value.decode("latin-1"))
        if len(seen[b"host"]) > 1 or len(seen[b"origin"]) > 1:
            return "more than one Host or Origin header"
        host = seen[b"host"][0] if seen[b"host"] else None
        origin = seen[b"origin"][0] if seen[b"origin"] else None
        return self.refusal(host, origin)


def _normal_origin(origin: str) -> str | None:
    """``scheme://host[:port]`` in lower case with the default port left out; None when
    ``origin`` is not one (``null``, a path, credentials)."""
    try:
        parts = urlsplit(origin.strip())
        port = parts.port
    except ValueError:
        return None
    scheme, name = parts.scheme.lower(), (parts.hostname or "").rstrip(".")
    if scheme not in DEFAULT_PORTS or not name or parts.username or parts.password:
        return None
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        return None
    shown = f"[{name}]" if ":" in name else name
    if port is None or port == DEFAULT_PORTS[scheme]:
        return f"{scheme}://{shown}"
    return f"{scheme}://{shown}:{port}"


def _origin_parts(normal: str) -> tuple[str, str, int]:
    parts = urlsplit(normal)
    scheme = parts.scheme
    return scheme, parts.hostname or "", parts.port or DEFAULT_PORTS[scheme]
