"""The errors modalmorph raises, all ``ValueError`` subclasses but the divergence of a
time integration (an ``ArithmeticError``): catch ``ValueError`` for any bad input."""

from __future__ import annotations

__all__ = ["OptionError", "ShapeError", "InputFileError", "ModelError",
           "MorphDivergedError"]


class OptionError(ValueError):
    """An option out of its range, of the wrong type, or unknown."""


class ShapeError(ValueError):
    """An object that is not a valid shape (too few nodes, not finite, no area, ...)."""


class InputFileError(ValueError):
    """A file that cannot be read as a shape or frames; the message names the file."""


class ModelError(ValueError):
    """A physical model that cannot be built (a Gram matrix singular at the given sigma)."""


class MorphDivergedError(ArithmeticError):
    """The time integration diverged; ``.steps`` says when, the message what to change."""

    def __init__(self, message: str, steps: int):
        super().__init__(message)
        self.steps = steps
