"""Recorded motion: channelsets, bound channelsets, playback, vectorised sampling and posture graphs.

Seed 002, sections 3.4.1-3.4.2. Modules, bottom up:

* :mod:`~server.motion.channelset` — the in-memory channelset (contiguous float32 arrays) and sharedchannels;
* :mod:`~server.motion.channelset_file` — ``*.chset.env`` text through the Peabody parser, and the writer
  (importing this package registers the ``channelset`` block with the Peabody loader);
* :mod:`~server.motion.cache` — ``.npz`` binary caches (in a cache directory) and :func:`load_channelset`;
* :mod:`~server.motion.binding` — bound channelsets (index maps onto figures' pose vectors);
* :mod:`~server.motion.playback` — the frame arithmetic of a play (the scalar reference of sampling);
* :mod:`~server.motion.sampling` — :class:`ClipLibrary`, sampling thousands of soldiers per call;
* :mod:`~server.motion.recording` — ``write_channelset`` from recorded channels, ``reroot_figure_channel``;
* :mod:`~server.motion.posture_graph` / :mod:`~server.motion.posture_change` — ``.graph`` files, shortest
  paths in time and bound posture graphs (the soldier manager executes posture changes).
"""

from __future__ import annotations

from server.motion import channelset_file as _channelset_file  # noqa: F401  (registers the block)
from server.motion.binding import BoundChannelset, bind_channelset
from server.motion.cache import load_channelset
from server.motion.channelset import Channelset, SharedChannel, make_channelset
from server.motion.errors import BindingError, ChannelsetError, PostureGraphError
from server.motion.posture_change import (
    BoundPostureGraph,
    bind_posture_graph,
    load_posture_graph,
)
from server.motion.posture_graph import PostureGraph, parse_posture_graph, read_posture_graph
from server.motion.recording import Recording, reroot_figure_channel, write_channelset
from server.motion.sampling import ClipLibrary, LibrarySample

__all__ = [
    "BindingError",
    "BoundChannelset",
    "BoundPostureGraph",
    "Channelset",
    "ChannelsetError",
    "ClipLibrary",
    "LibrarySample",
    "PostureGraph",
    "PostureGraphError",
    "Recording",
    "SharedChannel",
    "bind_channelset",
    "bind_posture_graph",
    "load_channelset",
    "load_posture_graph",
    "make_channelset",
    "parse_posture_graph",
    "read_posture_graph",
    "reroot_figure_channel",
    "write_channelset",
]
