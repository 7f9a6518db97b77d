"""tf2's exception hierarchy, as :class:`~bagtools.errors.BagtoolsError` so the CLI prints one line.

``TransformException`` is the base; ``LookupException`` (unknown frame, or a
loop in the tree), ``ConnectivityException`` (frames in unconnected trees),
``ExtrapolationException`` (a time outside the data; its subclasses say which
way, as tf2's ``Backward``/``Forward``/``NoDataForExtrapolationException``) and
``InvalidArgumentException`` (empty or '/'-prefixed frame ids, NaN, non-unit
quaternions, non-integer stamps).
"""

from __future__ import annotations

from pathlib import Path

from bagtools.errors import BagtoolsError


class TransformException(BagtoolsError):
    """Any tf failure. ``path`` is the bag the buffer was loaded from, if any."""

    def __init__(self, message: str, path: str | Path | None = None) -> None:
        super().__init__(message, path)


class LookupException(TransformException):
    """A frame that the buffer does not know, or a tree that contains a loop."""


class ConnectivityException(TransformException):
    """The two frames are in different (unconnected) trees."""


class ExtrapolationException(TransformException):
    """The requested time is outside the data of a transform on the path."""


class BackwardExtrapolationException(ExtrapolationException):
    """The requested time is before the earliest sample ("extrapolation into the past")."""


class ForwardExtrapolationException(ExtrapolationException):
    """The requested time is after the latest sample ("extrapolation into the future")."""


class NoDataForExtrapolationException(ExtrapolationException):
    """The transform has a single sample and the requested time is not its stamp."""


class InvalidArgumentException(TransformException):
    """A malformed argument: empty or '/'-prefixed frame id, NaN, non-unit quaternion, float stamps."""
