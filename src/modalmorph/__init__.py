"""modalmorph: physically based temporal estimation of the deformation between two shapes.

An implementation of Tavares & Pinho (2005), "Temporal estimation of the deformation
between objects by a physical methodology", with Sclaroff's Gaussian finite element,
modal matching, Horn alignment, Lagrange's dynamic equilibrium and strain energy.

The names below load their modules on first use (PEP 562), so that ``import modalmorph``
and the command line start without numpy and scipy until they are needed.
"""

from importlib import import_module

from .version import __version__

# public name -> the module that defines it
_WHERE = {
    "DEFAULT_SIGMA": "core.element", "FEModel": "core.model", "MATERIALS": "core.material",
    "Material": "core.material", "POLYETHYLENE": "core.material", "RUBBER": "core.material",
    "UNIT": "core.material", "Modes": "core.modes", "rayleigh": "core.modes",
    "Shape": "core.shape", "resample": "core.shape", "Similarity": "core.align",
    "align": "core.align", "MorphDivergedError": "errors", "read_shape": "io",
    "Matching": "matching", "match": "matching", "MatchOptions": "options",
    "MorphOptions": "options", "TrackOptions": "options", "Morph": "pipeline",
    "morph": "pipeline", "Simulation": "simulation", "Track": "tracking", "track": "tracking",
    "set_blas_threads": "threads", "Strain": "cardiac", "StrainOptions": "options",
    "strain": "cardiac", "Stance": "pedobarography", "StanceOptions": "options",
    "register_footprints": "pedobarography", "stance": "pedobarography",
}
# subpackages and modules reachable as attributes (mm.io.read_frames, mm.figures, ...)
_MODULES = ("apps", "cardiac", "core", "datasets", "errors", "figures", "io", "matching",
            "options", "pedobarography", "phantoms", "pipeline", "simulation", "threads",
            "tracking")

__all__ = ["__version__", *sorted(_WHERE)]


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(import_module(f".{_WHERE[name]}", __name__), name)
    elif name in _MODULES:
        value = import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module 'modalmorph' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted({*globals(), *_WHERE, *_MODULES})
