"""Options as data: the one schema of the library, the recorded parameters, the TOML
config, the command-line flags and the web form.

Every option is a field of a frozen dataclass that validates itself on construction:

- :class:`MatchOptions`: how :func:`modalmorph.match` finds correspondences;
- :class:`MorphOptions`: the physical model, the loads, the time integration and the stop
  test of :func:`modalmorph.morph`;
- :class:`ReadOptions`: how shape files become shapes (:func:`modalmorph.io.read_shape`);
- :class:`OutputOptions`: what the command line writes besides the results;
- :class:`TrackOptions`, :class:`StrainOptions`, :class:`StanceOptions`: sequences,
  myocardial strain, pressure plates.

The machinery is in :mod:`~modalmorph.options.base`, the classes in
:mod:`~modalmorph.options.method` and :mod:`~modalmorph.options.studies`.

A field's ``metadata`` holds what the command line and the form need: ``help`` (one or
two sentences), ``group`` and, where the values are a closed set, ``choices``. Its type
is ``kind`` (see :func:`parse_value`). Add an option by adding a field: the flag, the
config key, the form entry and the record in ``result.json`` follow.

Flat names: one namespace (the config file, the flags, the form) holds the fields of
every class; a :class:`MatchOptions` field whose name a :class:`MorphOptions` field also
has is prefixed ``match_`` there (``match_sigma``, ``match_modes``). See
:func:`flat_fields` and :func:`split`.
"""

from __future__ import annotations

from dataclasses import fields

from ..errors import OptionError
from .base import (
    C_MAX,
    CORRESPONDENCES,
    DT_RANGE,
    FRAME_SPACINGS,
    FREE_MOTIONS,
    K_RANGE,
    LOADS,
    METHODS,
    OBJECTS,
    REFERENCES,
    ROTATIONS,
    SCHEMES,
    STEP_MESHES,
    parse_value,
)
from .method import MatchOptions, MorphOptions, OutputOptions, ReadOptions, TrackOptions
from .studies import StanceOptions, StrainOptions

__all__ = [
    "MatchOptions", "MorphOptions", "ReadOptions", "OutputOptions", "TrackOptions",
    "StrainOptions", "StanceOptions",
    "OPTION_CLASSES", "REFERENCES", "CORRESPONDENCES", "flat_fields", "parameters", "split",
    "split_overrides", "parse_value", "METHODS", "ROTATIONS", "FREE_MOTIONS", "LOADS",
    "SCHEMES", "OBJECTS", "FRAME_SPACINGS", "STEP_MESHES", "K_RANGE", "DT_RANGE", "C_MAX",
]

OPTION_CLASSES = (ReadOptions, MatchOptions, MorphOptions, OutputOptions)


def flat_fields(classes=OPTION_CLASSES):
    """``[(flat name, class, field)]`` of the given option classes, in order: the one
    namespace of the config file, the flags and the form (see the module's docstring)."""
    names = {f.name for cls in classes if cls is not MatchOptions for f in fields(cls)}
    return [((f"match_{f.name}" if cls is MatchOptions and f.name in names else f.name),
             cls, f) for cls in classes for f in fields(cls)]


def split_overrides(overrides: dict, *, where: str) -> tuple[dict, dict]:
    """Keyword overrides of :func:`modalmorph.morph` as ``(MorphOptions fields,
    MatchOptions fields)``: the matcher's options under their flat names (``rotation``,
    ``method``, ``reject``, ``match_sigma``, ``match_modes``); unknown names refused."""
    morph_names = {f.name for f in fields(MorphOptions)}
    match_names = {flat: f.name for flat, cls, f in flat_fields() if cls is MatchOptions}
    unknown = sorted(set(overrides) - morph_names - set(match_names))
    if unknown:
        raise OptionError(f"unknown {where} option {unknown[0]!r}; known: "
                          f"{', '.join(sorted(morph_names | set(match_names)))}")
    return ({k: v for k, v in overrides.items() if k in morph_names},
            {match_names[k]: v for k, v in overrides.items() if k in match_names})


def parameters(morph) -> dict:
    """What a morph used, by flat name (``result.json``'s ``parameters``): its
    :meth:`MorphOptions.record` with the values resolved for its object (``sigma``,
    ``modes`` as a count, ``model_nodes`` as the model's node count, ``solver``) and the
    matcher's options when known."""
    flat = {f.name: name for name, cls, f in flat_fields() if cls is MatchOptions}
    from_match = {} if morph.match_options is None else {
        flat[name]: value for name, value in morph.match_options.record().items()}
    resolved = morph.resolved
    return {**morph.options.record(),
            "sigma": resolved.sigma, "modes": resolved.modes,
            "model_nodes": resolved.model_nodes, "solver": resolved.solver, **from_match}


def split(values: dict, classes=OPTION_CLASSES, *, where: str = "options") -> dict:
    """``{class: instance}`` from flat values (parsed or text); unknown names refused."""
    table = {flat: (cls, f) for flat, cls, f in flat_fields(classes)}
    unknown = sorted(set(values) - set(table))
    if unknown:
        raise OptionError(f"{where}: unknown option {unknown[0]!r}; known: "
                          f"{', '.join(table)}")
    kwargs, out = {cls: {} for cls in classes}, {}
    try:
        for flat, value in values.items():
            cls, f = table[flat]
            kwargs[cls][f.name] = parse_value(flat, f.metadata["kind"], value)
        for cls, kw in kwargs.items():
            try:
                out[cls] = cls(**kw)
            except OptionError as exc:  # named as the user names it: match_modes, not modes
                own = {f.name: flat for flat, (c, f) in table.items() if c is cls}
                field, _, rest = str(exc).partition(" ")
                raise OptionError(f"{own.get(field, field)} {rest}") from None
    except OptionError as exc:
        raise OptionError(f"{where}: {exc}") from None
    return out

