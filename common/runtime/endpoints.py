"""Zenoh endpoints as users write them, `<protocol>/<address>`, checked without Zenoh: the mission
file's `network.connect`, the tools' `--connect` and `--listen`. One rule for all of them, so a bad
endpoint gets the same line wherever it is given (the bus adds Zenoh's own parse, `check_endpoints`)."""

from __future__ import annotations

import ipaddress
import re

IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")  # Zenoh's links over IP: the address ends in :PORT
EXAMPLE = "tcp/127.0.0.1:7447"
_HOST_NAME = re.compile(r"[A-Za-z0-9_.\-]+")


def split(endpoint: str) -> tuple[str, str]:
    """(protocol, address) of an endpoint, without its ?metadata and #config."""
    protocol, _, address = endpoint.split("#", 1)[0].split("?", 1)[0].partition("/")
    return protocol, address


def endpoint_problem(endpoint: str, listen: bool = False) -> str | None:
    """Why `endpoint` cannot be used to connect (or, with `listen`, to listen, where port 0 asks
    for a free one), in one line naming it; None when it can."""
    protocol, address = split(endpoint)
    if protocol.startswith("unixsock") and address:
        return None
    if protocol not in IP_PROTOCOLS or not address:
        return f"{endpoint!r} is not <protocol>/<address>, e.g. {EXAMPLE}"
    host, colon, port = address.rpartition(":")
    lowest = 0 if listen else 1
    if not (colon and host and port.isdigit() and lowest <= int(port) <= 65535):
        return f"{endpoint!r} needs a port {lowest}-65535, e.g. {EXAMPLE}"
    literal = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if host.startswith("[") or literal.replace(".", "").isdigit():
        try:
            ipaddress.ip_address(literal)
        except ValueError:
            return f"{endpoint!r}: {literal!r} is not an IP address"
    elif not _HOST_NAME.fullmatch(host):
        return f"{endpoint!r}: {host!r} is not a host name"
    return None
