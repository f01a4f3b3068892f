"""The options every client command shares to reach a server with tokens or TLS: ``--token`` (default the
environment's ``TTES_TOKEN``, so the secret need not show in ``ps``), ``--tls`` and ``--tls-ca FILE``.

Commands call :func:`add_link_options` on their parser and :func:`link_credentials` when they run, and hand
the :class:`~client_stub.link.auth.Credentials` to the links they open. The role each command asks for stays
its own (ping: observer; the others: controller); a higher role's token is accepted for it.
"""

from __future__ import annotations

import argparse
import os

from client_stub.link.auth import Credentials, tls_context

TOKEN_ENV = "TTES_TOKEN"


def add_link_options(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group(
        "server credentials",
        "needed by a server with role tokens (any server listening beyond loopback) or TLS",
    )
    g.add_argument(
        "--token",
        help=f"the role's token, sent in HELLO (default: ${TOKEN_ENV}; prefer it: flags show in ps)",
    )
    g.add_argument(
        "--tls", action="store_true", help="speak TLS, checking the server against the system's CAs"
    )
    g.add_argument(
        "--tls-ca",
        metavar="FILE",
        type=_ca_file,
        help="speak TLS, trusting the CA or server certificate(s) in this PEM file",
    )


def _ca_file(path: str) -> str:
    """A usable --tls-ca file (checked while parsing, so a bad one exits 2 before anything connects)."""
    try:
        tls_context(path)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return path


def link_credentials(args: argparse.Namespace) -> Credentials:
    """The token (the flag, else ``$TTES_TOKEN``, read now) and the TLS context the options ask for."""
    token = args.token if args.token is not None else os.environ.get(TOKEN_ENV, "")
    tls = tls_context(args.tls_ca) if (args.tls or args.tls_ca) else None
    return Credentials(token, tls)


def link_error(exc: BaseException) -> BaseException | None:
    """The LinkError (a refused or failed connection) that ended a client command's trio run, also from inside
    trio's exception groups (a nursery wraps what its body raised); None when something else ended it."""
    from client_stub.link.client import LinkError

    while isinstance(exc, BaseExceptionGroup):
        found = exc.subgroup(LinkError)
        if found is None:
            return None
        exc = found.exceptions[0]
    return exc if isinstance(exc, LinkError) else None
