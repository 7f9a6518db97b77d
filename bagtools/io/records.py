"""What a bag reader yields and says: topics (:class:`TopicInfo`), serialized and decoded messages
(:class:`RawRecord`, :class:`Record`), the errors a damaged bag may raise underneath (:data:`READ_ERRORS`) and how
one is said in a line (:func:`one_line`)."""

from __future__ import annotations

import importlib
import struct
from dataclasses import dataclass
from typing import Any

from rosbags.highlevel import AnyReaderError
from rosbags.rosbag1 import ReaderError as Rosbag1ReaderError
from rosbags.rosbag2 import ReaderError as Rosbag2ReaderError
from rosbags.serde import SerdeError
from rosbags.typesys import TypesysError


def _apsw_errors() -> tuple[type[Exception], ...]:
    try:
        import apsw
    except ImportError:  # rosbags reads sqlite3 through apsw; without it there is nothing to catch
        return ()
    return (apsw.Error,)


def _zstd_errors() -> tuple[type[Exception], ...]:
    """The zstd libraries' errors (damaged compressed data): rosbags decompresses a rosbag2 file (or message)
    compressed with zstd through ``backports.zstd`` or ``compression.zstd``, the mcap library through ``zstandard``."""
    errors: list[type[Exception]] = []
    for module in ("compression.zstd", "backports.zstd", "zstandard"):
        try:
            errors.append(importlib.import_module(module).ZstdError)
        except (ImportError, AttributeError):
            continue
    return tuple(errors)


def one_line(err: BaseException) -> str:
    """An exception as a short single line: its type and its first 200 characters."""
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text[:200]}" if text else type(err).__name__


# What rosbags (and apsw, numpy, zstd underneath) raise on damaged files and messages.
READ_ERRORS = (AnyReaderError, Rosbag1ReaderError, Rosbag2ReaderError, TypesysError, SerdeError, OSError, KeyError,
                ValueError,
                TypeError, AssertionError, IndexError, AttributeError, OverflowError, MemoryError, EOFError,
                struct.error, *_apsw_errors(), *_zstd_errors())


@dataclass(frozen=True)
class TopicInfo:
    """A topic of a bag: its name, ROS 2 style message type and message count."""

    name: str
    msgtype: str
    count: int


@dataclass(frozen=True, slots=True)
class RawRecord:
    """One serialized message: topic, type, bag (log) time in ns and the raw bytes."""

    topic: str
    msgtype: str
    log_time_ns: int
    raw: bytes | memoryview
    publisher: str = ""  # the node that published it, where the bag says (a ROS 1 connection's callerid)


@dataclass(frozen=True, slots=True)
class Record:
    """One deserialized message (a rosbags message object) with its bag time in ns."""

    topic: str
    msgtype: str
    log_time_ns: int
    msg: Any
    publisher: str = ""
