"""The machinery of the options: fields with the metadata of the command line and the
form (:func:`option`), the validating base class (:class:`Options`), the value parser of
text and TOML (:func:`parse_value`) and the shared checks; the closed sets of choices."""

from __future__ import annotations

import math
from dataclasses import asdict, field, fields, replace
from numbers import Integral, Real

from ..core.element import MAX_SIGMA, MIN_SIGMA
from ..core.material import MATERIALS, Material
from ..errors import OptionError

__all__ = ["Options", "option", "parse_value", "is_number", "is_int", "is_label",
           "check_range", "check_sigma", "check_modes", "check_damping", "METHODS",
           "ROTATIONS", "FREE_MOTIONS", "LOADS", "SCHEMES", "OBJECTS", "FRAME_SPACINGS",
           "STEP_MESHES", "REFERENCES", "CORRESPONDENCES", "K_RANGE", "DT_RANGE", "C_MAX"]

METHODS = ("auto", "local", "global")
ROTATIONS = ("auto", "free", "none")
FREE_MOTIONS = ("similarity", "none")
LOADS = ("consistent", "nodal")
SCHEMES = ("implicit", "explicit")
OBJECTS = ("largest", "center", "all")  # or a number of the image's objects
FRAME_SPACINGS = ("time", "path")
STEP_MESHES = ("none", "ply", "obj")  # OutputOptions.meshes
REFERENCES = ("previous", "first")
CORRESPONDENCES = ("nearest", "normal", "modal")
# Ranges beyond which the integration is meaningless or overflows (fuzz suite; method.md §4).
K_RANGE = (1e-6, 1e6)
DT_RANGE = (1e-6, 1e6)
C_MAX = 10.0


def option(default, help: str, *, group: str, kind: str, choices=None, flag: str | None = None):
    """A field with the metadata of the command line and the form."""
    return field(default=default, metadata=dict(help=help, group=group, kind=kind,
                                                choices=choices, flag=flag))


class Options:
    """Shared behaviour: validation on construction, ``replace``, the record."""

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            choices = f.metadata.get("choices")
            if choices and value not in choices and not (
                    f.metadata["kind"] == "object" and is_label(value)):
                label = " or a label number >= 1" if f.metadata["kind"] == "object" else ""
                raise OptionError(f"{f.name} must be one of {', '.join(map(str, choices))}"
                                  f"{label}, got {value!r}")
        self._check()

    def _check(self):
        pass

    def replace(self, **changes):
        """A copy with some options changed (validated); unknown names are refused. No
        changes: this object itself (frozen, already validated)."""
        if not changes:
            return self
        known = {f.name for f in fields(self)}
        unknown = sorted(set(changes) - known)
        if unknown:
            raise OptionError(f"unknown {type(self).__name__} option {unknown[0]!r}; "
                              f"known: {', '.join(sorted(known))}")
        return replace(self, **changes)

    def record(self) -> dict:
        """Every option as plain JSON values (the material as its four properties)."""
        out = asdict(self)
        for name, value in out.items():
            if isinstance(value, tuple):
                out[name] = list(value)
        if isinstance(getattr(self, "material", None), Material):
            mat = self.material
            out["material"] = dict(name=mat.name, E=mat.E, nu=mat.nu, rho=mat.rho)
        return out


def parse_value(name: str, kind: str, value):
    """A value of the given kind from text (the flags, the form) or from TOML.

    Kinds: ``bool``, ``int``, ``float``, ``str``; ``modes`` ("all", a count or a fraction
    such as "2/3" or 0.66); ``damping`` (one or two numbers); ``point`` (two numbers x,y);
    ``material`` (a name or three numbers E, nu, rho); ``object`` (largest, center or a
    label number). ``None`` and empty text give ``None`` (the default).
    """
    if value is None or isinstance(value, str) and not value.strip():
        return None
    if not isinstance(value, str):
        return _typed(name, kind, value)
    text = value.strip()
    if kind == "bool":
        if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
            raise OptionError(f"{name} must be true or false, got {text!r}")
        return text.lower() in ("true", "1", "yes")
    if kind == "str":
        return text
    if kind == "object":
        return int(text) if text.isdigit() else text
    if kind == "modes" and text.lower() == "all":
        return None
    if kind == "material" and text in MATERIALS:
        return MATERIALS[text]
    try:
        numbers = [_number(name, token) for token in text.replace(",", " ").split()]
    except OptionError:
        if kind == "material":  # a name not known
            raise OptionError(f"{name} must be one of {', '.join(MATERIALS)} or three "
                              f"numbers E nu rho, got {text!r}") from None
        raise
    return _typed(name, kind, numbers[0] if len(numbers) == 1 else numbers)


def _typed(name, kind, value):
    """Check a non-text value's type for its kind; lists become tuples."""
    if kind == "material":
        if isinstance(value, Material):
            return value
        if isinstance(value, str) and value in MATERIALS:
            return MATERIALS[value]
        if isinstance(value, list | tuple) and len(value) == 3 and all(map(is_number, value)):
            return Material(*map(float, value), name="custom")
        raise OptionError(f"{name} must be one of {', '.join(MATERIALS)} or three numbers "
                          f"E nu rho, got {value!r}")
    if kind == "point":
        if not (isinstance(value, list | tuple) and len(value) == 2
                and all(map(is_number, value))):
            raise OptionError(f"{name} must be two numbers x,y, got {value!r}")
        return tuple(map(float, value))
    if kind == "damping" and isinstance(value, list | tuple):
        if len(value) not in (1, 2) or not all(map(is_number, value)):
            raise OptionError(f"{name} takes one or two ratios, got {value!r}")
        return float(value[0]) if len(value) == 1 else tuple(map(float, value))
    expected = {"bool": bool, "int": Integral, "float": Real, "str": str, "modes": Real,
                "damping": Real, "object": (str, Integral)}[kind]
    if not isinstance(value, expected) or isinstance(value, bool) and kind != "bool":
        raise OptionError(f"{name} has the wrong type ({type(value).__name__}) for "
                          f"{kind}")
    return float(value) if kind == "float" else value


def _number(name, token):
    try:
        if "/" in token:
            num, den = token.split("/")
            return float(num) / float(den)
        return int(token) if token.lstrip("+-").isdigit() else float(token)
    except (ValueError, ZeroDivisionError):
        raise OptionError(f"{name} must be a number, got {token!r}") from None


def is_number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)


def is_int(value) -> bool:
    return isinstance(value, Integral) and not isinstance(value, bool)


def is_label(value) -> bool:
    return is_int(value) and value >= 1


def check_range(name, value, low, high, unit):
    if not (is_number(value) and low <= value <= high):
        raise OptionError(f"{name} must be a number in [{low:g}, {high:g}] ({unit}), "
                          f"got {value!r}")


def check_sigma(sigma):
    if sigma is not None and not (is_number(sigma) and MIN_SIGMA <= sigma <= MAX_SIGMA):
        raise OptionError(f"sigma must be None (chosen per shape) or a number between "
                          f"{MIN_SIGMA:g} and {MAX_SIGMA:g} (x mean node spacing), "
                          f"got {sigma!r}")


def check_modes(modes):
    if modes is None or is_int(modes) and modes >= 1:
        return
    if is_number(modes) and isinstance(modes, float) and 0 < modes <= 1:
        return
    raise OptionError(f"modes must be None (all), a count >= 1 or a fraction in (0, 1], "
                      f"got {modes!r}")


def check_damping(damping):
    if is_number(damping) and damping > 0:
        return
    if isinstance(damping, tuple) and len(damping) == 2 and all(
            is_number(x) and x >= 0 for x in damping):
        return
    raise OptionError(f"damping must be a ratio > 0 or two ratios >= 0, got {damping!r}")

