"""The one client link to a Jack/TTES server: a trio-native client over
:class:`protocol.connection.Connection`, a thin threaded adapter for render loops, and the server spawner."""
