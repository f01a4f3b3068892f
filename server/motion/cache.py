"""Binary caches of channelset files: ``X.chset.npz`` in a cache directory, never beside ``X.chset.env``.

Parsing a big channelset text file costs far more than loading its arrays, so the first load writes the arrays
to an ``.npz`` (no pickles). A cache is used only when it is readable, has this format version and records the
text file's current size and modification time; otherwise the text is parsed again and the cache rewritten
(atomically, and silently skipped when the folder cannot be written).

The caches live in a cache directory (:func:`cache_dir`: ``$TTES_CACHE_DIR``, else
``$XDG_CACHE_HOME/jack-ttes`` or ``~/.cache/jack-ttes``; the server's ``cache_dir`` setting overrides it),
named by the source's resolved path: a client's ``load_channelset`` must never write files into the data
directory (issue 17).
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from server.motion.channelset import Channelset, SharedChannel

FORMAT_VERSION = 3
CACHE_DIR_ENV = "TTES_CACHE_DIR"
log = logging.getLogger(__name__)


def cache_dir() -> Path:
    """The default cache folder: ``$TTES_CACHE_DIR``, ``$XDG_CACHE_HOME/jack-ttes``, ``~/.cache/...``."""
    if os.environ.get(CACHE_DIR_ENV):
        return Path(os.environ[CACHE_DIR_ENV]).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "jack-ttes"


def cache_path(path: str | Path, directory: str | Path | None = None) -> Path:
    """``.../X.chset.env`` → ``<cache dir>/X.chset-<hash of the resolved path>.npz``."""
    path = Path(path)
    stem = path.name.removesuffix(".env")
    key = hashlib.sha1(str(path.resolve()).encode()).hexdigest()[:16]
    return Path(directory if directory is not None else cache_dir()) / f"{stem}-{key}.npz"


def _strings(values: list[str]) -> np.ndarray:
    return np.array(values, dtype=str) if values else np.zeros(0, dtype="<U1")


def save_npz(chset: Channelset, target: str | Path, source_stat: os.stat_result | None = None) -> None:
    """Write ``chset`` to ``target`` atomically (temp file + rename)."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    chans = chset.channels
    arrays: dict[str, Any] = {
        "format_version": np.array(FORMAT_VERSION),
        "name": np.array(chset.name),
        "fps": np.array(chset.fps, dtype=np.float64),
        "source": np.array(chset.source or ""),
        "source_size": np.array(source_stat.st_size if source_stat else -1, dtype=np.int64),
        "source_mtime_ns": np.array(source_stat.st_mtime_ns if source_stat else -1, dtype=np.int64),
        "ch_name": _strings([c.name for c in chans]),
        "ch_type": _strings([c.type for c in chans]),
        "ch_proto": _strings([c.protofiletype for c in chans]),
        "ch_object": _strings([c.object for c in chans]),
        "ch_column": np.array([c.column for c in chans], dtype=np.int64),
        "ch_width": np.array([c.width for c in chans], dtype=np.int64),
        "joint_data": chset.joint_data,
        "fig_pos": chset.fig_pos,
        "fig_quat": chset.fig_quat,
        "fig_root": chset.fig_root,
        "root_names": _strings(list(chset.root_names)),
        "stride_length": np.array(np.nan if chset.stride_length is None else chset.stride_length),
        "ground_speed": np.array(np.nan if chset.ground_speed is None else chset.ground_speed),
        "release_frame": np.array(-1 if chset.release_frame is None else chset.release_frame, np.int64),
        "end_offset": np.array(chset.end_offset if chset.end_offset is not None else [np.nan] * 3),
    }
    fd, tmp = tempfile.mkstemp(prefix="." + target.name, suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_npz(path: str | Path, source_stat: os.stat_result | None = None) -> Channelset | None:
    """The cached channelset, or None when the cache is missing, unreadable, stale or of another version."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if int(z["format_version"]) != FORMAT_VERSION:
                return None
            if source_stat is not None and (
                int(z["source_size"]) != source_stat.st_size
                or int(z["source_mtime_ns"]) != source_stat.st_mtime_ns
            ):
                return None
            channels = tuple(
                SharedChannel(str(n), str(t), str(p), str(o), int(c), int(w))  # type: ignore[arg-type]
                for n, t, p, o, c, w in zip(
                    z["ch_name"],
                    z["ch_type"],
                    z["ch_proto"],
                    z["ch_object"],
                    z["ch_column"],
                    z["ch_width"],
                    strict=True,
                )
            )
            source = str(z["source"]) or None
            stride, speed = float(z["stride_length"]), float(z["ground_speed"])
            release, offset = int(z["release_frame"]), [float(v) for v in z["end_offset"]]
            return Channelset(
                name=str(z["name"]),
                fps=float(z["fps"]),
                channels=channels,
                joint_data=z["joint_data"],
                fig_pos=z["fig_pos"],
                fig_quat=z["fig_quat"],
                fig_root=z["fig_root"],
                root_names=tuple(str(s) for s in z["root_names"]),
                source=source,
                stride_length=None if np.isnan(stride) else stride,
                ground_speed=None if np.isnan(speed) else speed,
                release_frame=None if release < 0 else release,
                end_offset=None if np.isnan(offset).any() else (offset[0], offset[1], offset[2]),
            )
    except (OSError, KeyError, ValueError, TypeError, zipfile.BadZipFile, EOFError):
        return None


def load_channelset(
    path: str | Path, *, use_cache: bool = True, directory: str | Path | None = None
) -> Channelset:
    """Load the one channelset in a ``.chset.env`` file, through its ``.npz`` cache (in ``directory``, default
    :func:`cache_dir`) when fresh."""
    from server.motion.channelset_file import read_channelset  # parsing pulls in the Peabody language

    path = Path(path)
    if not use_cache:
        return read_channelset(path)
    st = path.stat()
    cpath = cache_path(path, directory)
    cached = load_npz(cpath, st)
    if cached is not None:
        return cached
    chset = read_channelset(path)
    try:
        save_npz(chset, cpath, st)
    except OSError as exc:  # an unwritable cache folder still works, just slower
        log.debug("cannot write channelset cache %s: %s", cpath, exc)
    return chset
