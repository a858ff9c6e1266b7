"""3D morphs of point sets (issue 16): a truncated modal basis and the matcher's own pairs,
on warped, turned, subsampled, shuffled copies with a known ground truth."""

import numpy as np
from scipy.spatial import cKDTree

import modalmorph as mm
from modalmorph.simulation import Simulation

from .test_match3d import case

# The end shape's mean distance to the target points, both ways, in target spacings: a
# shape on the target's surface is about a spacing from its nearest sample (measured on
# the true positions of these cases: 0.2-0.4 spacings without noise).
END_SPACINGS = 1.0


def both_ways(end, tgt):
    h = cKDTree(tgt).query(tgt, k=2)[0][:, 1].mean()
    return cKDTree(tgt).query(end)[0].mean() / h, cKDTree(end).query(tgt)[0].mean() / h


def test_truncated_basis_carries_the_similarity():
    """100 modes of a 600-node model (the sparse solver's kind of basis): the affine
    motions added by Rayleigh-Ritz carry the large turn and shift, and the morph converges
    as the complete basis does; the augmented modes are M-orthonormal."""
    src, tgt, truth = case(600, 60, 0.0)
    pairs = np.c_[np.arange(600), cKDTree(tgt).query(truth)[1]]
    r = mm.morph(src, tgt, matching=pairs, model_nodes=600, solver="sparse", modes=100)
    assert r.converged, r.message
    assert max(both_ways(r.shapes[-1], tgt)) < END_SPACINGS
    sim = Simulation(mm.Shape(src), mm.Shape(tgt), pairs,
                     mm.MorphOptions(model_nodes=600, solver="sparse", modes=100))
    Phi = sim.modes.shapes
    assert Phi.shape[1] > 100 + 12  # the affine motions and a 100-node copy's modes
    np.testing.assert_allclose(Phi.T @ sim.model.apply_mass(Phi), np.eye(Phi.shape[1]), atol=1e-8)
    assert np.all(np.diff(sim.modes.frequencies) >= 0)


def test_matcher_driven_morph_converges():
    """Warp + turn + shuffle, 2000 points, the matcher's pairs (about a spacing off): the
    stop test measures the surfaces both ways, so the morph converges onto the target."""
    src, tgt, truth = case(2000, 90, 0.0)
    r = mm.morph(src, tgt, matching=mm.match(src, tgt))
    assert r.converged, r.message
    assert max(both_ways(r.shapes[-1], tgt)) < END_SPACINGS
    assert r.distance <= 0.005 * mm.Shape(tgt).size
