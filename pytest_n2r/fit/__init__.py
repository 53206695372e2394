"""Fitting a scene field to a capture: the training loop, its row-sparse optimizer and compiled step kernels.

It sits above :mod:`pytest_n2r.field` (the representation and its sampling maths) and
:mod:`pytest_n2r.render` (held-out evaluation renders); neither imports it.
"""

from .evaluate import FIT_RENDER, evaluate_views
from .field_fit import FitResult, fit

__all__ = ["FIT_RENDER", "FitResult", "evaluate_views", "fit"]
