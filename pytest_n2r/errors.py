"""The exceptions pytest-n2r raises.

Every error the package raises on purpose is an :class:`N2RError`, so a caller can catch them all at once.
Argument errors are also a :class:`ValueError` (bad value) or :class:`TypeError` (bad type), so code that
already catches those keeps working. Messages name the argument, file or field, what was found and what
was expected.
"""

from __future__ import annotations

__all__ = [
    "N2RError",
    "InvalidArgument",
    "InvalidType",
    "IngestError",
    "SceneFileError",
    "FitError",
    "SUTError",
    "SUTOutputError",
    "SUTNotDeterministic",
    "CallTimeout",
    "BaselineError",
    "MetricArgumentError",
    "MetricUndefined",
    "UnfinishedScene",
]


class N2RError(Exception):
    """Base class of every error raised by pytest-n2r."""


class InvalidArgument(N2RError, ValueError):
    """An argument has the right type but a value outside what is accepted (non-finite, out of range)."""


class InvalidType(N2RError, TypeError):
    """An argument or a returned value has the wrong type or shape."""


class IngestError(N2RError):
    """A capture (images folder, COLMAP model, transforms.json) cannot be turned into a scene."""


class SceneFileError(N2RError):
    """A ``.n2r`` scene file is missing, truncated, of another format version or inconsistent."""


class FitError(N2RError):
    """Fitting a scene field failed (diverged to NaN, no usable views, ...)."""


class SUTError(N2RError):
    """The system under test raised; the original exception is chained (``__cause__``)."""


class SUTOutputError(InvalidType):
    """The system under test returned something a metric cannot use (None, NaN, wrong shape)."""


class SUTNotDeterministic(N2RError):
    """The system under test gave two different outputs for the same image."""


class CallTimeout(N2RError):
    """A render or SUT call ran longer than its limit (``--n2r-timeout``)."""


class BaselineError(N2RError):
    """A baseline file that cannot be used: missing, unreadable, from another version, or malformed."""


class MetricArgumentError(InvalidArgument):
    """A metric's own argument does not fit the views or outputs it is given (a plane through a camera's centre,
    a homography without a plane under a camera translation, ``top_k`` not below the number of classes): the
    test's mistake, not the SUT's."""


class MetricUndefined(N2RError):
    """A metric has no value for this pair of outputs, so the pair tests nothing (e.g. no keypoint lies in
    the region both views see). Inside a Hypothesis test the example is rejected instead of raised."""


class UnfinishedScene(UserWarning):
    """A scene file whose fit did not finish (a checkpoint of a crashed or interrupted fit) is being tested on:
    its verdicts measure a field still being fitted."""
