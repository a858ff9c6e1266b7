"""Isotropic linear elastic materials that fill the modelled objects."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Material", "MATERIALS", "POLYETHYLENE", "RUBBER", "UNIT"]


@dataclass(frozen=True)
class Material:
    """An isotropic, homogeneous, linear elastic material.

    Parameters
    ----------
    E : float
        Young's modulus, > 0 (Pa in the presets).
    nu : float
        Poisson's ratio, in (-1, 0.5) (strictly below 0.5: incompressible is singular).
    rho : float
        Density, > 0 (kg/m^3 in the presets).
    name : str, optional
        A label for reports.

    Notes
    -----
    For a homogeneous object driven by loads proportional to ``k``, only ``nu`` changes the
    *shape* of the modes; ``E`` and ``rho`` set the units of stiffness and time. The model
    works on the object normalised to unit RMS radius, so its angular frequencies are
    ``sqrt(E / rho)`` times a number that depends only on the geometry, ``nu`` and sigma;
    for the same object of size ``L`` (in metres) they are divided by ``L``.
    :func:`modalmorph.morph` measures ``k`` in units of ``E`` and time in units of
    ``sqrt(rho / E)`` (on the normalised object), so its results do not depend on the units
    either.
    """

    E: float
    nu: float
    rho: float
    name: str = "custom"

    def __post_init__(self):
        for key in ("E", "nu", "rho"):
            value = getattr(self, key)
            if not isinstance(value, int | float) or value != value or abs(value) == float("inf"):
                raise ValueError(f"Material {key} must be a finite number, got {value!r}")
        if self.E <= 0:
            raise ValueError(f"Material E (Young's modulus) must be > 0, got {self.E}")
        if self.rho <= 0:
            raise ValueError(f"Material rho (density) must be > 0, got {self.rho}")
        if not -1.0 < self.nu < 0.5:
            raise ValueError(f"Material nu (Poisson's ratio) must be in (-1, 0.5), got {self.nu}")

    @property
    def lame(self) -> tuple[float, float]:
        """Lamé parameters (lambda, mu) for 3D and 2D plane strain."""
        lam = self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))
        mu = self.E / (2 * (1 + self.nu))
        return lam, mu

    def lame_2d(self, plane: str) -> tuple[float, float]:
        """Lamé parameters for a 2D model: ``plane="stress"`` or ``"strain"``."""
        lam, mu = self.lame
        if plane == "stress":
            return 2 * lam * mu / (lam + 2 * mu), mu  # lambda* = E nu / (1 - nu^2)
        if plane == "strain":
            return lam, mu
        raise ValueError(f"plane must be 'stress' or 'strain', got {plane!r}")


# Low-density polyethylene, the paper's virtual material (Tavares & Pinho 2005, §6 use
# polyethylene without giving values). Typical handbook values for LDPE: E = 0.2 GPa,
# nu = 0.46, rho = 920 kg/m^3 (e.g. Callister, *Materials Science and Engineering*,
# Table B.2/B.3, which lists E = 0.17-0.28 GPa and rho = 0.917-0.932 g/cm^3 for LDPE).
POLYETHYLENE = Material(E=0.2e9, nu=0.46, rho=920.0, name="polyethylene")
# Natural rubber: E = 1.5 MPa, nu = 0.49, rho = 930 kg/m^3 (nearly incompressible).
RUBBER = Material(E=1.5e6, nu=0.49, rho=930.0, name="rubber")
# A unit material with nu = 0.3, handy for checks: frequencies in units of sqrt(E/rho).
UNIT = Material(E=1.0, nu=0.3, rho=1.0, name="unit")

MATERIALS = {mat.name: mat for mat in (POLYETHYLENE, RUBBER, UNIT)}
