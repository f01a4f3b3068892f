"""Sans-IO protocols: the TTES wire protocol and DIS.

Bytes in, events out; events in, bytes out. No sockets, no trio.
"""
