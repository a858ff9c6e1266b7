"""modalmorph: physically based temporal estimation of the deformation between two shapes.

An implementation of Tavares & Pinho (2005), "Temporal estimation of the deformation
between objects by a physical methodology", with Sclaroff's Gaussian finite element,
modal matching, Horn alignment, Lagrange's dynamic equilibrium and strain energy.
"""

from .core.align import Similarity, align
from .core.element import DEFAULT_SIGMA
from .core.material import MATERIALS, POLYETHYLENE, RUBBER, UNIT, Material
from .core.model import FEModel
from .core.modes import Modes, rayleigh
from .core.shape import Shape, resample
from .errors import MorphDivergedError
from .io import read_shape
from .matching import Matching, match
from .options import MatchOptions, MorphOptions
from .pipeline import Morph, morph
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
