"""`ttes front`: a front-end for image generators in front of N shards (``ttes server --shard K/N``).

It accepts clients over the same TCP protocol as ``ttes server`` (same handshake, update tables, FIGURE:
a client cannot tell the difference), subscribes to every shard's poses on the publish/subscribe fabric,
merges them into its clients' update streams, and sends each client's requests to the shard that owns
the soldier (index K modulo N). It takes the settings of ``ttes server`` (same data dir: the same soldiers
and tables). Needs the [fabric] extra; docs/SCALING.md says how to lay out shards and front-ends.
"""

from __future__ import annotations

import argparse

from ttes.arguments import count
from ttes.commands.server import add_fabric_options, add_server_parser


def register(sub: argparse._SubParsersAction) -> None:
    p = add_server_parser(sub, "front", "serve image generators from shards over the fabric", __doc__ or "")
    p.add_argument(
        "--shards", type=count(1, 256), required=True, help="how many shards (ttes server --shard K/N)"
    )
    p.add_argument(
        "--front",
        metavar="K/M",
        default="0/1",
        help="this is front-end K of M in front of the same shards: it allots soldier indices from its own "
        "share and tells the others what it creates (default 0/1: the only one)",
    )
    add_fabric_options(p)
