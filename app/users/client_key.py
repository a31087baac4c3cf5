"""Which client a dashboard login attempt counts against: its key in the login limits.

Both login limits (attempts per minute per client, and the wait per (account, client) in
`ops_login_failure`) count a client by this key, never by the raw address. An IPv6 client is
counted by its /64: that is one customer's prefix (an ISP hands out a /64 or more, and a host
picks any address in it, fresh privacy addresses by the hour), so counted by full address a
guesser took a new address for every attempt and met a fresh allowance each time. An IPv4
client is counted by its address, and an IPv4-mapped IPv6 address (`::ffff:192.0.2.7`, what a
dual-stack socket or proxy reports for an IPv4 peer) as that IPv4 address, or one IPv4 client
would be a whole /64 of one key and its plain-IPv4 self another; likewise an IPv4 client
translated (NAT64's `64:ff9b::/96`) or tunnelled (Teredo) to IPv6.

An address that is no IP address (a trusted proxy's `X-Forwarded-For` of `unknown` or any
text, a client the server was not told of) is counted under one shared key, UNREADABLE_CLIENT:
kept as sent, such text was a fresh allowance per spelling, and a few kilobytes of it were more
than PostgreSQL's index on `ops_login_failure` takes, which turned the login into a 503 saying
the database was unavailable. Those
clients share one allowance; clients with a readable address never meet it.
"""

from __future__ import annotations

import ipaddress

IPV6_CLIENT_PREFIX = 64
# Parenthesised, so no IP address or network is ever written the same way.
UNREADABLE_CLIENT = "(no IP address)"


def login_client_key(address: str | None) -> str:
    """The key a login attempt from `address` is counted under: `192.0.2.7` for an IPv4
    client, `2001:db8:1:2::/64` for an IPv6 one, UNREADABLE_CLIENT for anything else."""
    if not address:
        return UNREADABLE_CLIENT
    try:
        parsed = ipaddress.ip_address(address)
    except ValueError:
        return UNREADABLE_CLIENT
    if isinstance(parsed, ipaddress.IPv4Address):
        return parsed.compressed
    embedded = _embedded_ipv4(parsed)
    if embedded is not None:
        return embedded.compressed
    return ipaddress.IPv6Network((parsed, IPV6_CLIENT_PREFIX), strict=False).compressed


# RFC 6052's well-known prefix for IPv4 clients translated to IPv6 (NAT64, SIIT-DC).
NAT64_PREFIX = ipaddress.IPv6Network("64:ff9b::/96")


def _embedded_ipv4(address: ipaddress.IPv6Address) -> ipaddress.IPv4Address | None:
    """The IPv4 client behind an IPv6 address that carries one: IPv4-mapped (`::ffff:a.b.c.d`),
    translated (RFC 6052's `64:ff9b::/96`) or tunnelled (Teredo, the client's own address).
    Counted by its /64, every IPv4 client behind one translator or relay was one key, so one
    stranger's guesses made them all wait (a review)."""
    if address.ipv4_mapped is not None:
        return address.ipv4_mapped
    if address in NAT64_PREFIX:
        return ipaddress.IPv4Address(int(address) & 0xFFFFFFFF)
    if address.teredo is not None:
        return address.teredo[1]
    return None
