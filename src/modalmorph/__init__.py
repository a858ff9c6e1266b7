"""modalmorph: physically based temporal estimation of the deformation between two shapes.

An implementation of Tavares & Pinho (2005), "Temporal estimation of the deformation
between objects by a physical methodology", with Sclaroff's Gaussian finite element,
modal matching, Horn alignment, Lagrange's dynamic equilibrium and strain energy.
"""

from .align import Similarity, align
from .element import DEFAULT_SIGMA
from .errors import MorphDivergedError
from .io import read_shape
from .matching import Matching, match
from .material import MATERIALS, POLYETHYLENE, RUBBER, UNIT, Material
from .model import FEModel
from .modes import Modes, rayleigh
from .options import MatchOptions, MorphOptions
from .pipeline import Morph, morph
from .shape import Shape, resample
from .simulation import Simulation
from .track import Track, TrackOptions, track
from .version import __version__

__all__ = [
    "DEFAULT_SIGMA",
    "FEModel",
    "MATERIALS",
    "Material",
    "MatchOptions",
    "Matching",
    "Modes",
    "Morph",
    "MorphDivergedError",
    "MorphOptions",
    "POLYETHYLENE",
    "RUBBER",
    "Shape",
    "Similarity",
    "Simulation",
    "Track",
    "TrackOptions",
    "UNIT",
    "__version__",
    "align",
    "match",
    "morph",
    "rayleigh",
    "read_shape",
    "resample",
    "track",
]
