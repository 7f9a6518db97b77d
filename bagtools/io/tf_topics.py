"""Read a bag's /tf and /tf_static into :class:`~bagtools.io.decode.TfArrays`."""

from __future__ import annotations

import numpy as np

from bagtools.io.decode import TF_TYPES, TfArrays, decode_tf_message
from bagtools.io.reader import BagReader, Record
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
        self._dynamic: list[TfArrays] = []
        self._static: list[TfArrays] = []
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
        for rec in progress(bag.messages(present), total=total, desc="reading tf", unit="msg"):
            self.add(rec)

    def add(self, rec: Record) -> None:
        """Decode a record of one of the tf topics (others are ignored)."""
        if rec.topic == self.static_topic:
            self._static.append(decode_tf_message(rec.msg))
        elif rec.topic == self.tf_topic:
            arrays = decode_tf_message(rec.msg).published_by(rec.publisher)
            self._dynamic.append(arrays)
            self._dynamic_arrival_ns.extend([rec.log_time_ns] * len(arrays))

    def arrays(self) -> tuple[TfArrays, TfArrays]:
        """(dynamic, static) transforms collected so far, each in bag-time order."""
        return TfArrays.concatenate(self._dynamic), TfArrays.concatenate(self._static)

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
