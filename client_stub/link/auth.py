"""What a client shows a server: its role's token (HELLO) and, for a TLS server, whom it trusts.

One value per run, built once by the ``ttes`` client commands (``ttes/link_options.py``) and applied to every
link they open, so no command handles a token or a TLS context itself (docs/PROTOCOL.md §14).
"""

from __future__ import annotations

import ssl
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from client_stub.link.client import Client


@dataclass(frozen=True)
class Credentials:
    """A role token ("" = none: a local server without tokens) and a TLS context (None = plain TCP)."""

    token: str = field(default="", repr=False)  # a secret: never in a repr, a log line or an error
    tls: ssl.SSLContext | None = None

    def apply(self, client: Client) -> Client:
        """Set them on a link before it opens; returns it."""
        client.token = self.token
        client.tls = self.tls
        return client


def tls_context(cafile: str | None = None) -> ssl.SSLContext:
    """A TLS client context that checks the server's certificate and name: against the PEM ``cafile``
    (a private CA or a self-signed server), else the system's CAs. ValueError when the file cannot be used."""
    try:
        return ssl.create_default_context(cafile=cafile)
    except (OSError, ssl.SSLError) as exc:
        raise ValueError(f"cannot load {cafile}: {getattr(exc, 'strerror', None) or exc}") from None
