"""Network addresses of ``performer run``'s settings: ``HOST:PORT`` endpoints (OSC targets,
the WebSocket server, the OSC control input) and the sender networks allowed to steer."""

from __future__ import annotations

import ipaddress
from collections.abc import Sequence

from models.errors import ConfigError, short_repr

IpNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network


def parse_endpoint(text: str, what: str = "endpoint") -> tuple[str, int]:
    """``"HOST:PORT"`` (``"[::1]:PORT"`` for IPv6) → (host, port); ConfigError if malformed."""
    host, sep, port = str(text).rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not (port.isascii() and port.isdigit()) or not 1 <= int(port) <= 65535:
        raise ConfigError(f"{what} address must be HOST:PORT with a port in 1..65535, got {text!r}")
    return host, int(port)


def parse_control_endpoint(text: str | int) -> tuple[str, int]:
    """``"PORT"`` (host 127.0.0.1) or ``"HOST:PORT"`` (``"[::1]:PORT"`` for IPv6) -> (host, port)."""
    s = str(text).strip()
    if s.isascii() and s.isdigit():
        s = f"127.0.0.1:{s}"
    return parse_endpoint(s, "control_osc")


def parse_networks(items: Sequence[str]) -> list[IpNetwork]:
    """``--control-allow`` values (an address, or a network like ``192.168.1.0/24``) -> networks."""
    nets = []
    for item in items:
        try:
            nets.append(ipaddress.ip_network(str(item).strip(), strict=False))
        except ValueError:
            raise ConfigError(f"control_allow must be an IP address or network like 192.168.1.0/24, "
                              f"got {short_repr(item)}") from None
    return nets
