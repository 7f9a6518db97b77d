"""Read a bag's /tf and /tf_static into :class:`~bagtools.io.decode.TfArrays`."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from bagtools.io.cdr import tf_from_cdr
from bagtools.io.decode import TF_TYPES, TfArrays, TfRows, tf_arrays, tf_rows
from bagtools.io.reader import BagReader
from bagtools.io.records import Record
from bagtools.progress import progress

TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"


class TfCollector:
    """Accumulates the transforms of /tf and /tf_static records fed to it in bag order.

    Lets a pass that reads other topics too collect the tf data on the way,
    instead of reading the bag twice.
    """

    def __init__(self, tf_topic: str = TF_TOPIC, static_topic: str = TF_STATIC_TOPIC) -> None:
        self.tf_topic = tf_topic
        self.static_topic = static_topic
        self._dynamic: list[tuple] = []  # TfRows rows, in bag order
        self._static: list[tuple] = []
        self._publishers: list[str] = []  # of each dynamic row
        self._dynamic_arrival_ns: list[int] = []

    @property
    def topics(self) -> tuple[str, str]:
        return (self.tf_topic, self.static_topic)

    def check(self, bag: BagReader) -> None:
        """Raise :class:`~bagtools.errors.TopicError` if a tf topic has another type than TFMessage."""
        for topic in self.topics:
            if topic in bag.topics:
                bag.require_topic(topic, TF_TYPES)

    def read(self, bag: BagReader) -> None:
        """Read every message of the tf topics the bag has (with a progress bar)."""
        present = [t for t in self.topics if t in bag.topics]
        total = sum(bag.topics[t].count for t in present)
        records = bag.messages(present, from_cdr=self.from_cdr)
        for rec in progress(records, total=total, desc="reading tf", unit="msg"):
            self.add(rec)

    @property
    def from_cdr(self) -> dict[str, Callable[[bytes | memoryview], TfRows | None]]:
        """The CDR decoder of each tf topic, for :meth:`~bagtools.io.BagReader.messages`."""
        return {topic: tf_from_cdr for topic in self.topics}

    def add(self, rec: Record) -> None:
        """Collect a record of one of the tf topics (others are ignored): a deserialized message, or the
        :class:`~bagtools.io.decode.TfRows` of :func:`~bagtools.io.cdr.tf_from_cdr`."""
        if rec.topic not in self.topics:
            return
        rows = rec.msg if isinstance(rec.msg, TfRows) else tf_rows(rec.msg)
        if rec.topic == self.static_topic:
            self._static.extend(rows)
        else:
            self._dynamic.extend(rows)
            self._publishers.extend([rec.publisher] * len(rows))
            self._dynamic_arrival_ns.extend([rec.log_time_ns] * len(rows))

    def arrays(self) -> tuple[TfArrays, TfArrays]:
        """(dynamic, static) transforms collected so far, each in bag-time order."""
        return tf_arrays(self._dynamic, self._publishers), tf_arrays(self._static)

    def dynamic_arrival_ns(self) -> np.ndarray:
        """(N,) int64 bag (arrival) time of each dynamic transform, aligned with ``arrays()[0]``."""
        return np.asarray(self._dynamic_arrival_ns, dtype=np.int64)


def read_tf_arrays(bag: BagReader, tf_topic: str = TF_TOPIC, static_topic: str = TF_STATIC_TOPIC) -> tuple[TfArrays, TfArrays]:
    """Return (dynamic, static) transforms of the bag, each in bag-time order.

    A topic the bag lacks contributes nothing; a topic of another type than
    TFMessage raises :class:`~bagtools.errors.TopicError`.
    """
    collector = TfCollector(tf_topic, static_topic)
    collector.check(bag)
    collector.read(bag)
    return collector.arrays()
