"""The eigensolvers of a model, behind one dispatch.

Each solver is a module with ``solve(model, n) -> Modes`` for an
:class:`~modalmorph.core.model.FEModel`:

- :mod:`.dense`: the exact model, every interaction, LAPACK; all modes or the lowest.
- :mod:`.sparse`: the truncated model (interactions beyond ``cutoff_radius`` dropped),
  the lowest ``n`` modes by shift-invert Lanczos on a sparse factor.
- :mod:`.multilevel`: the truncated model, the lowest ``n`` modes by a coarse start and
  LOBPCG, without a factorisation (3D point sets, where the sparse factor does not fit);
  :mod:`.lobpcg` is the block LOBPCG it runs.

:func:`choose` resolves a solver name (``"auto"`` by the size of the model) into a
:class:`Solver`, which says whether the model it solves is truncated.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ...errors import OptionError
from ..element import AUTO_DENSE_MAX_DOF, DEFAULT_CUTOFF
from ..modes import Modes
from . import dense, multilevel, sparse

__all__ = ["Solver", "SOLVERS", "AUTO_MULTILEVEL_MIN_NODES", "choose"]

SOLVERS = ("auto", "dense", "sparse", "multilevel")
# 3D shapes from this many nodes use the multilevel solver (sparse: 1 GB at 2000; method.md §7).
AUTO_MULTILEVEL_MIN_NODES = 2500


@dataclass(frozen=True)
class Solver:
    """An eigensolver as a model uses it.

    Attributes
    ----------
    name : str
        ``"dense"``, ``"sparse"`` or ``"multilevel"``.
    solve : callable
        ``solve(model, n) -> Modes``, the lowest ``n`` modes.
    truncated : bool
        Whether the model it solves keeps only the interactions within its cutoff radius
        and only its lowest modes can be computed (``n`` required, at most ``d * m - 2``).
    cutoff : float
        The default relative size below which a truncated model drops an interaction.
    """

    name: str
    solve: Callable[..., Modes]
    truncated: bool
    cutoff: float


_SOLVERS = {
    "dense": Solver("dense", dense.solve, truncated=False, cutoff=DEFAULT_CUTOFF),
    "sparse": Solver("sparse", sparse.solve, truncated=True, cutoff=DEFAULT_CUTOFF),
    "multilevel": Solver("multilevel", multilevel.solve, truncated=True,
                         cutoff=multilevel.MULTILEVEL_CUTOFF),
}


def choose(solver: str, dim: int, m: int) -> Solver:
    """The solver named ``solver`` (one of ``SOLVERS``) for a model of ``m`` nodes in ``dim``
    dimensions: ``"auto"`` picks dense up to ``AUTO_DENSE_MAX_DOF`` degrees of freedom
    (``dim * m``), multilevel for 3D shapes of ``AUTO_MULTILEVEL_MIN_NODES`` nodes or
    more, and sparse otherwise."""
    if solver not in SOLVERS:
        raise OptionError(f"solver must be one of {SOLVERS}, got {solver!r}")
    if solver == "auto":
        solver = ("dense" if dim * m <= AUTO_DENSE_MAX_DOF else
                  "multilevel" if dim == 3 and m >= AUTO_MULTILEVEL_MIN_NODES else "sparse")
    return _SOLVERS[solver]
