"""Rendering: views of a scene at a camera and pose."""

from .view import OUTPUTS, RenderedView

__all__ = ["OUTPUTS", "RenderedView"]
