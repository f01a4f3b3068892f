"""The `ttes` command line: the one entry point over server, protocol and client_stub."""
