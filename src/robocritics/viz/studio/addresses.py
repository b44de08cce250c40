"""This machine's addresses, for the URLs the studio prints when it binds every interface (0.0.0.0 or ::)."""

from __future__ import annotations

import socket

__all__ = ["local_addresses"]


def local_addresses(ipv6: bool = False) -> list[str]:
    """The addresses of this machine's interfaces (IPv4; also IPv6 when ``ipv6``), non-loopback ones first, then
    127.0.0.1: what another machine (or this one) can open. Read from the interfaces, no packet is sent."""
    found: list[str] = []
    family = (socket.AF_INET, socket.AF_INET6) if ipv6 else (socket.AF_INET,)
    try:
        for info in socket.getaddrinfo(socket.gethostname(), None):
            if info[0] in family:
                found.append(info[4][0].split("%")[0])
    except OSError:
        pass
    found += _interface_addresses()
    ordered = []
    for address in found:
        if address not in ordered and not address.startswith(("127.", "::1", "fe80")):
            ordered.append(address)
    return ordered + ["127.0.0.1"]


def _interface_addresses() -> list[str]:
    """IPv4 address of every interface (Linux ``SIOCGIFADDR``); [] where that is not available."""
    try:
        import fcntl
        import struct
    except ImportError:  # pragma: no cover - not Linux/Unix
        return []
    addresses = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for _, name in socket.if_nameindex():
            try:
                packed = fcntl.ioctl(sock.fileno(), 0x8915, struct.pack("256s", name.encode()[:15]))  # SIOCGIFADDR
            except OSError:
                continue  # an interface without an IPv4 address
            addresses.append(socket.inet_ntoa(packed[20:24]))
    return addresses
