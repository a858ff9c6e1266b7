"""
Choosing options: spring stiffness, time step and damping
=========================================================

The morph's options are fields of :class:`modalmorph.MorphOptions` (flags of ``modalmorph
morph``, keys of its ``--config`` file). ``k`` (``--k``) is the stiffness of the springs
pulling each node to its partner, in units of one node's own stiffness; ``dt`` (``--dt``)
the time step in units of 1/omega_ref; ``damping`` (``--damping``) one
stiffness-proportional ratio (the default, 1) or two Rayleigh ratios (the paper's 0.005
and 0.03 oscillate about the target). The curves show the mean distance to the target per
step on the bundled heart pair; why the defaults are what they are is in the Method page.
"""

import matplotlib.pyplot as plt

import modalmorph as mm
from modalmorph.datasets import heart_shape

source, target = heart_shape("diastole"), heart_shape("systole")
matching = mm.match(source, target)
variants = {"defaults (k=100, dt=0.1, damping=1)": {},
            "k=10": {"k": 10},
            "dt=0.05": {"dt": 0.05},
            "the paper's damping (0.005, 0.03)": {"damping": (0.005, 0.03), "max_steps": 40}}
results = {name: mm.morph(source, target, matching=matching, **options)
           for name, options in variants.items()}

fig, ax = plt.subplots(figsize=(7.5, 4.4), layout="constrained")
for name, r in results.items():
    ax.plot(r.mean_distance, marker=".", label=f"{name}: {r.steps} steps, {r.stop_reason}")
ax.set_xlabel("step")
ax.set_ylabel("mean distance to the target (px)")
ax.set_yscale("log")
ax.legend(fontsize=8)

summary = "; ".join(f"{name}: {r.steps} steps" for name, r in results.items())
print(summary)
print(mm.MorphOptions())
