"""The app's form: generated from the option classes, parsed as the command line parses,
and bounded by the app's limits (:mod:`modalmorph.apps.policy`)."""

from __future__ import annotations

import re
from http import HTTPStatus

from ..datasets import hand_shape, heart_shape
from ..options import flat_fields
from .policy import APP_LIMITS, AppLimits, Refused
from .runs import FORM_CLASSES, Settings, default_text

__all__ = ["morph_options", "parse_options", "examples", "field_of", "check_run"]


def morph_options() -> list[dict]:
    """The form: one entry per option of :data:`modalmorph.apps.runs.FORM_CLASSES` (matching,
    physics, loads and time integration, stopping), by flat name.

    Generated from the fields' metadata, so that a new option appears in the form by
    itself. Each entry has ``name``, ``group``, ``kind`` ("bool", "choice" or "text"),
    ``default`` (JSON), ``default_text`` (as typed in the form), ``choices`` (or None),
    ``summary`` (the help's first sentence) and ``help``.
    """
    options = []
    for name, cls, f in flat_fields(FORM_CLASSES):
        meta = f.metadata
        choices = list(meta["choices"]) if meta["kind"] == "str" and meta["choices"] \
            else None
        kind = "bool" if meta["kind"] == "bool" else "choice" if choices else "text"
        default = cls().record()[f.name]
        text = default_text(f)
        summary = re.split(r"(?<=\.)\s", meta["help"], maxsplit=1)[0]
        options.append(dict(name=name, group=meta["group"], kind=kind, default=default,
                            default_text=text, choices=choices, summary=summary,
                            help=meta["help"]))
    return options


def parse_options(values: dict) -> Settings:
    """The run's settings from the form's values (text, or booleans for check boxes).

    An empty field takes the default; text is parsed as on the command line
    (:func:`modalmorph.options.parse_value`: ``40``, ``2/3``, ``0.5 1``, ``rubber``,
    ``1e5 0.3 1000``).

    Raises
    ------
    OptionError
        For an unknown option or an invalid value (the message names the option).
    """
    given = {name: value for name, value in values.items()
             if not (isinstance(value, str) and not value.strip())}
    return Settings.from_flat(given, FORM_CLASSES, where="options")


def examples() -> dict:
    """The bundled pairs, as in ``modalmorph demo``: name -> (label, loader)."""
    return {
        "heart": ("heart: left ventricle, end-diastole -> end-systole",
                  lambda: (heart_shape("diastole"), heart_shape("systole"))),
        "hands": ("hands: hand 0 (120 nodes) -> hand 3 (140 nodes)",
                  lambda: (hand_shape(0, 120), hand_shape(3, 140))),
    }


def field_of(message: str) -> str | None:
    """The option a message names first (option messages start with the name)."""
    names = {o["name"] for o in morph_options()}
    words = re.findall(r"\w+", message)
    return next((w for w in words[:3] if w in names), None)


def check_run(settings: Settings, nodes: int, limits: AppLimits = APP_LIMITS) -> None:
    """:class:`Refused` (400, naming the option) when a run would exceed the app's bounds
    on ``max_steps``, ``model_nodes`` or nodes x steps (``nodes``: the larger shape's)."""
    morph = settings.morph
    if morph.max_steps > limits.max_steps:
        raise Refused(HTTPStatus.BAD_REQUEST, f"max_steps: the app runs at most "
                      f"{limits.max_steps} steps (max_steps limit), got {morph.max_steps}",
                      "max_steps")
    if morph.model_nodes > limits.max_model_nodes:
        raise Refused(HTTPStatus.BAD_REQUEST, f"model_nodes: the app models at most "
                      f"{limits.max_model_nodes} nodes (max_model_nodes limit), got "
                      f"{morph.model_nodes}", "model_nodes")
    if nodes * morph.max_steps > limits.max_node_steps:
        most = max(1, limits.max_node_steps // nodes)
        raise Refused(HTTPStatus.BAD_REQUEST, f"max_steps: {nodes} nodes x {morph.max_steps} "
                      f"steps is over the app's bound of {limits.max_node_steps} node-steps "
                      f"(max_node_steps limit): at most {most} steps for these shapes",
                      "max_steps")
