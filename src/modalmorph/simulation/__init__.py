"""The time integration of a morph: a driver, a modal system, a stop test and a result.

Laid out as scipy's ``integrate/_ivp``:

- :mod:`.system`: :class:`~.system.ModalSystem`, built once from (source, target, pairs,
  options): the model and the basis of its coordinates (:mod:`.basis`: the modes
  superposed, or with every mode the element's whitened basis), the reference scales,
  the modal stiffness with the similarity motions free, the springs, the damping, the
  Newmark integrator and the load targets (method.md §4, §7);
- :mod:`.stop`: one stop test per kind of object (contour, surface or 3D point set,
  pairs only), chosen once (method.md §5);
- :mod:`.driver`: :class:`Simulation`, the state, the history and the stop test:
  :meth:`~Simulation.step`, :meth:`~Simulation.stop_test`, :meth:`~Simulation.run`,
  :meth:`~Simulation.result`;
- :mod:`.result`: the frozen :class:`Run` and the :class:`Resolved` values.

:func:`modalmorph.morph` is matching, optional alignment and :class:`Simulation`.
"""

from .basis import SPARSE_MODES
from .driver import Simulation
from .result import STOP_REASONS, Resolved, Run
from .system import reuse_systems

__all__ = ["Resolved", "Run", "STOP_REASONS", "Simulation", "SPARSE_MODES", "reuse_systems"]
