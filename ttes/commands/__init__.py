"""One module per `ttes` subcommand (group); each defines ``register(subparsers)``."""
