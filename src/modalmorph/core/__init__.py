"""The numerical core, numpy and scipy only, bottom up in the order of the method:
:mod:`.shape` (the validated ``Shape``), :mod:`.material`, :mod:`.element` (closed forms of
Sclaroff's Gaussian element), :mod:`.modes`, :mod:`.solvers` (dense, sparse and multilevel
eigensolvers), :mod:`.model` (``FEModel``: mass, stiffness, modes), :mod:`.dynamics`
(Newmark, the load targets), :mod:`.align` (Horn), :mod:`.energy` (strain energy per node)
and :mod:`.quality` (distances between curves, crossings, roughness)."""
