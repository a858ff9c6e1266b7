"""modalmorph: physically based temporal estimation of the deformation between two shapes.

An implementation of Tavares & Pinho (2005), "Temporal estimation of the deformation
between objects by a physical methodology", with Sclaroff's Gaussian finite element,
modal matching, Horn alignment, Lagrange's dynamic equilibrium and strain energy.
"""

from .element import DEFAULT_SIGMA, FEModel
from .material import MATERIALS, POLYETHYLENE, RUBBER, UNIT, Material
from .modes import Modes, rayleigh
from .shape import Shape

__version__ = "0.1.0"

__all__ = [
    "DEFAULT_SIGMA",
    "FEModel",
    "MATERIALS",
    "Material",
    "Modes",
    "POLYETHYLENE",
    "RUBBER",
    "Shape",
    "UNIT",
    "__version__",
    "rayleigh",
]
