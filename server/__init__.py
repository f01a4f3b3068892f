"""The TTES server.

A plain-numpy core (Peabody model, channelsets, posture graphs, soldier manager) under a thin trio layer.
"""
