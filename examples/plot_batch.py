"""
A batch of pairs: the manifest, the summary table and its figure
================================================================

``modalmorph batch manifest.csv --out DIR`` runs many pairs (and sequences) with the same
options, each written into ``DIR/<id>/`` exactly as ``modalmorph morph`` writes it, and a
summary table with one row per item. Here six pairs of bundled hands are written as CSV
files, listed in a manifest (one row per pair; one row overrides an option, ``k``), and
run through :func:`modalmorph.apps.batch.run`, the function behind the command, on a
local pool of one worker. :func:`modalmorph.figures.plot_batch` draws the summary:
final distance against strain energy per item (what ``--figures summary`` writes).
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from modalmorph import figures
from modalmorph.apps import batch
from modalmorph.datasets import load_hands

folder = Path(tempfile.mkdtemp())
hands = load_hands(range(7), n=80)
for i, hand in enumerate(hands):
    np.savetxt(folder / f"hand-{i}.csv", hand, delimiter=",", header="x,y", comments="")
rows = ["id,source,target,k"] + [f"h0-h{i},hand-0.csv,hand-{i}.csv,{60 if i == 6 else ''}"
                                 for i in range(1, 7)]
(folder / "manifest.csv").write_text("\n".join(rows) + "\n")

done = batch.run(batch.read_manifest(folder / "manifest.csv"), folder / "out",
                 engine=batch.Engine(kind="processes", workers=1))
results = list(batch.read_summary(folder / "out"))

fig, ax = plt.subplots(figsize=(6.5, 4.4), layout="constrained")
figures.plot_batch(results, ax=ax)

summary = f"{done.counts} by {done.engine}; files: {[f.name for f in done.files]}"
print(summary)
print((folder / "out" / "summary.csv").read_text().splitlines()[0])
