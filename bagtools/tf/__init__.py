"""tf for recorded bags: a tf2-compatible transform buffer with vectorized lookups.

``TfBuffer`` holds every transform of a bag and answers tf2's lookups
(``lookup``, ``lookup_full``, ``can_transform``) for one stamp or arrays of
stamps at once; the exceptions are tf2's.
"""

from bagtools.tf.buffer import TfBuffer
from bagtools.tf.track import format_stamp
from bagtools.tf.exceptions import (
    BackwardExtrapolationException,
    ConnectivityException,
    ExtrapolationException,
    ForwardExtrapolationException,
    InvalidArgumentException,
    LookupException,
    NoDataForExtrapolationException,
    TransformException,
)

__all__ = [
    "BackwardExtrapolationException", "ConnectivityException", "ExtrapolationException",
    "ForwardExtrapolationException", "InvalidArgumentException", "LookupException",
    "NoDataForExtrapolationException", "TfBuffer", "TransformException", "format_stamp",
]
