"""
Hands: one hand into another, coloured by load
==============================================

Two of the eight bundled hand outlines (statismo project), resampled to 150 nodes each by
arc length. The springs (19) pull each source node towards its partner; the figure on the
left colours the intermediate shapes by the load on each node, the one on the right shows
how the distance to the target and the strain energy evolve per time step.
"""

import matplotlib.pyplot as plt

import modalmorph as mm
from modalmorph import figures
from modalmorph.datasets import hand_shape

source, target = hand_shape(0, nodes=150), hand_shape(3, nodes=150)
result = mm.morph(source, target)

fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), layout="constrained")
figures.plot_shapes(result, color_by="load", ax=axes[0])
figures.plot_energy(result, ax=axes[1])

# %%
# ``result.message`` says how the run stopped, in the input's units (pixels here).
summary = f"{result.steps} steps, converged={result.converged}: {result.message}"
print(summary)
