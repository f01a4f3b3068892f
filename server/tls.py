"""TLS for the TTES port (optional): the server's ``ssl.SSLContext`` from the certificate and key the config
names. With it every connection is wrapped in ``trio.SSLStream`` before the first byte of the protocol, so
frames, client ids and role tokens are encrypted and the server is authenticated to clients that check its
certificate. Clients are not authenticated by TLS: roles still come from tokens (docs/PROTOCOL.md §14).
"""

from __future__ import annotations

import ssl

from server.config import ConfigError, ServerConfig


def server_context(config: ServerConfig) -> ssl.SSLContext | None:
    """None without ``tls_cert``; else a TLS ≥ 1.2 server context (ConfigError naming what cannot be read)."""
    if not config.tls_cert:
        return None
    ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    try:
        ctx.load_cert_chain(config.tls_cert, config.tls_key or None)
    except (OSError, ssl.SSLError) as exc:
        raise ConfigError(f"cannot load the certificate and key: {exc}", "tls_cert") from None
    return ctx
