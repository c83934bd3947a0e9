"""ukemi's exception classes.

Every error ukemi raises for bad input is a subclass of :class:`UkemiError` and of the builtin
that fits (``ValueError``, ``TypeError``, ``NotImplementedError``, ``RuntimeError``), so both
``except ukemi.UkemiError`` and ``except ValueError`` work.
"""

from __future__ import annotations


class UkemiError(Exception):
    """Base class of every ukemi error."""


class ModelError(UkemiError, ValueError):
    """A model field has an invalid value (raised when compiling)."""


class ShapeError(UkemiError, ValueError):
    """An array argument has the wrong shape."""


class InputError(UkemiError, ValueError):
    """An input value is invalid (non-finite, unknown name, out of range)."""


class ModelMismatchError(UkemiError, ValueError):
    """A state was made for a different model."""


class MjcfError(UkemiError, ValueError):
    """An MJCF file could not be loaded (the message names the element and line)."""


class UrdfError(UkemiError, ValueError):
    """A URDF file could not be loaded (the message names the element and line)."""


class UnsupportedError(UkemiError, NotImplementedError):
    """The model asks for a feature ukemi does not support (yet)."""


class ConvergenceError(UkemiError, RuntimeError):
    """A step's solve did not converge. ``info`` holds its report, ``state`` the last iterate."""

    def __init__(self, message: str, info=None, state=None, step_index: int | None = None):
        super().__init__(message)
        self.info = info
        self.state = state
        self.step_index = step_index


class InternalError(UkemiError):
    """A bug inside ukemi (a Rust panic caught at the boundary). Please report it."""


__all__ = [
    "UkemiError",
    "ModelError",
    "ShapeError",
    "InputError",
    "ModelMismatchError",
    "MjcfError",
    "UrdfError",
    "UnsupportedError",
    "ConvergenceError",
    "InternalError",
]
