"""Simulation: the time loop's stages on their own (build, step, stop test, result)."""

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial import ConvexHull

from modalmorph import MorphOptions, Shape, Simulation, morph
from modalmorph.simulation.stop import CurveStop, PairStop, SurfaceStop

from .conftest import sphere_points


def _ellipses(m=40):
    """A circle and an ellipse of m nodes, node i paired with node i."""
    t = np.linspace(0, 2 * np.pi, m, endpoint=False)
    a = np.c_[np.cos(t), np.sin(t)]
    return Shape(a), Shape(a * [1.6, 0.7] + [0.3, -0.2]), np.c_[np.arange(m), np.arange(m)]


def test_stages_one_at_a_time():
    a, b, pairs = _ellipses()
    # only max_steps can stop it: no tolerance reached, equilibrium disabled
    sim = Simulation(a, b, pairs, MorphOptions(tol=1e-12, equilibrium_tol=0, max_steps=2))
    assert sim.steps == 0 and sim.reason is None
    # step 0 is the source (through the model's normalised frame and back: round-off)
    assert_allclose(sim.shapes[0], a.points, atol=1e-12)
    with pytest.raises(RuntimeError, match="has not stopped"):
        sim.result()
    sim.step()
    assert sim.steps == 1 and sim.shapes.shape == (2, 40, 2)
    assert sim.mean_distance[1] < sim.mean_distance[0]  # the springs pull towards b
    assert sim.stop_test() is None
    sim.step()
    assert sim.mean_distance[2] < sim.mean_distance[1]
    assert sim.stop_test() == "max_steps" and sim.reason == "max_steps"
    result = sim.result()
    assert result.steps == 2 and not result.converged
    assert result.stop_reason == "max_steps"
    assert result.message.startswith("stopped at max_steps=2")
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.distance = 0.0


def test_stop_test_tolerance():
    a, b, pairs = _ellipses()
    sim = Simulation(a, b, pairs, MorphOptions(tol=0.05, equilibrium_tol=0))
    while sim.stop_test() is None:
        sim.step()
    assert sim.reason == "tolerance"
    result = sim.result()
    assert result.converged and result.distance <= 0.05 * b.size


def test_run_is_morph():
    """morph() is matching, alignment and the Simulation: the same numbers, bitwise."""
    a, b, pairs = _ellipses()
    options = MorphOptions(k=50, damping=(0.1, 0.5))
    steps = []
    sim = Simulation(a, b, pairs, options).run(progress=lambda s, d: steps.append(s))
    direct = morph(a, b, matching=pairs, options=options)
    assert steps == list(range(1, direct.steps + 1))
    for name in ("shapes", "loads", "energy", "node_energy", "mean_distance"):
        assert_array_equal(getattr(sim.result(), name), getattr(direct, name))


def test_bad_pairs_refused():
    a, b, _ = _ellipses()
    with pytest.raises(ValueError, match="no node is matched"):
        Simulation(a, b, np.zeros((0, 2), int))


def _objects(kind, rng):
    """A source, a target and node-to-node pairs of one kind of object."""
    if kind == "contour":
        return _ellipses()
    a = sphere_points(60, rng, radii=(1.0, 0.8, 0.6))
    b = a * [1.2, 0.7, 0.9] + 0.05
    pairs = np.c_[np.arange(60), np.arange(60)]
    if kind == "surface":
        faces = ConvexHull(a).simplices
        return Shape(a, faces=faces), Shape(b, faces=faces), pairs
    if kind == "points2d":
        return Shape(a[:, :2], ordered=False), Shape(b[:, :2], ordered=False), pairs
    return Shape(a), Shape(b), pairs


@pytest.mark.parametrize("kind, stop", [("contour", CurveStop), ("surface", SurfaceStop),
                                        ("points3d", SurfaceStop), ("points2d", PairStop)])
def test_state_is_small_and_the_stop_test_chosen_once(kind, stop, rng):
    """The driver holds a system, a stop test, a state and a history: at most 12
    attributes after a run, whatever the object; the stop test fits the object."""
    a, b, pairs = _objects(kind, rng)
    sim = Simulation(a, b, pairs, MorphOptions(max_steps=5)).run()
    assert len(vars(sim)) <= 12, sorted(vars(sim))
    assert type(sim.stop) is stop
    assert sim.result().steps == sim.steps == len(sim.history.shapes) - 1


def test_reuse_systems_same_numbers_and_released():
    """Inside reuse_systems, a second build on the same Shape with equal options reuses the
    model, modes and integrator, and its morph equals a fresh one bit for bit; another
    source or other options build their own; nothing is kept after the block."""
    from modalmorph.simulation import reuse_systems
    from modalmorph.simulation.system import ModalSystem

    a, b, pairs = _ellipses()
    c = Shape(b.points * [0.9, 1.1])
    options = MorphOptions()
    fresh = Simulation(a, c, pairs, options).run().result()
    with reuse_systems():
        first = ModalSystem.build(a, b, pairs, options)
        again = Simulation(a, c, pairs, options)
        other = ModalSystem.build(Shape(a.points), b, pairs, options)
        softer = ModalSystem.build(a, b, pairs, options.replace(k=0.5))
        assert again.system.model is first.model and again.system.newmark is first.newmark
        assert other.model is not first.model and softer.newmark is not first.newmark
        reused = again.run().result()
    for name in ("shapes", "loads", "energy", "node_energy", "mean_distance"):
        assert_array_equal(getattr(reused, name), getattr(fresh, name))
    assert ModalSystem.build(a, b, pairs, options).model is not first.model


def _modal(monkeypatch):
    """Make every system integrate in the modes themselves (the eigenproblem solved),
    as before the element basis."""
    from modalmorph.simulation import system
    from modalmorph.simulation.basis import ModeBasis

    monkeypatch.setattr(system, "ElementBasis", lambda model: ModeBasis(model, model.modes()))


@pytest.mark.parametrize("overrides", [
    {}, {"loads": "nodal", "damping": (0.5, 1.0)}, {"free_motion": "none"},
    {"scheme": "explicit", "k": 1, "max_steps": 30},
    {"scheme": "explicit", "k": 1, "max_steps": 30, "free_motion": "none"},
    {"model_nodes": 30}, {"c_x": 0.3, "c_v": 0.5}])
def test_every_mode_in_the_element_basis_equals_the_modes(monkeypatch, overrides):
    """With every mode superposed the system integrates in the element's whitened basis,
    an orthogonal change of the modal coordinates: the same morph to rounding (1e-9 of
    each array's largest value, measured 1e-13 .. 5e-10 on hearts, hands, glyphs and a 3D
    cloud) and the same steps, whatever the loads, scheme, damping, similarity rule or a
    reduced model."""
    a, b, pairs = _ellipses(60)
    b = Shape(b.points + 0.05 * np.sin(3 * a.points[:, ::-1]))
    options = MorphOptions(**overrides)
    element = Simulation(a, b, pairs, options)
    assert type(element.system.basis).__name__ == "ElementBasis"
    ours = element.run().result()
    _modal(monkeypatch)
    modal = Simulation(a, b, pairs, options)
    assert type(modal.system.basis).__name__ == "ModeBasis"
    ref = modal.run().result()
    assert ours.steps == ref.steps and ours.stop_reason == ref.stop_reason
    for name in ("shapes", "loads", "energy", "node_energy", "mean_distance"):
        want = getattr(ref, name)
        assert_allclose(getattr(ours, name), want, rtol=0, atol=1e-9 * np.abs(want).max(),
                        err_msg=name)


def test_element_basis_is_orthonormal_in_the_mass_and_spans_the_modes():
    """Phi^T M Phi = I like the modes; its stiffness has the modes' eigenvalues; its
    field at a reduced model's nodes applies Phi without forming it."""
    a, b, pairs = _ellipses(60)
    system = Simulation(a, b, pairs, MorphOptions(model_nodes=30)).system
    basis, field = system.basis, system.field
    n = basis.n
    assert_allclose(basis.mass_t(basis.shapes), np.eye(n), atol=1e-10)  # mass-normalised
    w2 = np.linalg.eigvalsh(basis.stiffness())
    assert_allclose(w2, system.modes.eigenvalues, rtol=1e-9, atol=1e-12 * w2.max())
    rng = np.random.default_rng(0)
    Phi, x, u = field.dense(), rng.normal(size=n), rng.normal(size=2 * a.m)
    assert Phi.shape == (2 * a.m, n)
    assert_allclose(field.dot(x), Phi @ x, atol=1e-12 * np.abs(Phi @ x).max())
    assert_allclose(field.tdot(u), Phi.T @ u, atol=1e-12 * np.abs(Phi.T @ u).max())
    assert_allclose(field.gram(), Phi.T @ Phi, atol=1e-12 * np.abs(Phi.T @ Phi).max())
    assert field.sq_norm() == pytest.approx(np.sum(Phi**2), rel=1e-12)


def test_similarity_free_full_is_the_diagonal_form_with_dependent_fields():
    """On a diagonal stiffness the full form equals the modal one, a dependent similarity
    field dropped by both (its eigenvalue in B^T K B: rounding, below 3e-16 of the
    largest over 200 seeds)."""
    from modalmorph.simulation.system import similarity_free, similarity_free_full

    for seed in range(20):
        rng = np.random.default_rng(seed)
        w = np.sort(rng.uniform(1, 100, 60))
        B = rng.normal(size=(60, 7)) * rng.uniform(0.1, 10, 7)
        B[:, 6] = B[:, 0] - 2 * B[:, 3]  # dependent
        want, (c, y) = similarity_free(w, B)
        got, (c_full, y_full) = similarity_free_full(np.diag(w**2), B)
        assert_allclose(got, want, atol=1e-10 * np.abs(want).max())
        x = rng.normal(size=60)  # the same similarity part, which K_el leaves out
        assert_allclose(c_full @ (y_full @ x), c @ (y @ x), atol=1e-9 * np.abs(x).max())
        assert_allclose(want @ (c @ (y @ x)), 0.0, atol=1e-9 * np.abs(want).max())


def test_lifted_stiffness_paths_are_the_lifted_copies_bitwise():
    """The morph's K_mod = K_el + kappa I is not formed: the damping made from K_el with
    its diagonal lifted is b times the lifted copy, bit for bit and in its (C) order;
    K_el is left as it was; the element basis hands its stiffness over and makes the
    same numbers again when asked."""
    from modalmorph.simulation.system import damping_matrix

    a, b, pairs = _ellipses(60)
    system = Simulation(a, b, pairs).system
    K_el, kappa = system.stiffness, system.kappa
    kept = K_el.copy()
    lifted = K_el.copy()
    lifted.flat[::len(K_el) + 1] += kappa
    for K in (K_el, np.asfortranarray(K_el)):
        C = damping_matrix(0.5, K, 2.0, uniform=True, lift=kappa)
        want = 0.5 * 2 / np.sqrt(2.0) * lifted
        assert np.array_equal(C, want) and C.flags.c_contiguous
    assert np.array_equal(K_el, kept)
    assert system.newmark.lift == kappa and system.newmark.K is K_el
    with pytest.raises(ValueError, match="one damping ratio"):
        damping_matrix((0.5, 0.5), K_el, 2.0, uniform=True, lift=kappa)
    basis = system.basis
    again = basis.stiffness()  # handed over during the build: made again
    taken = basis.take_stiffness()
    assert taken is again and basis._stiffness is None
    assert np.array_equal(basis.stiffness(), taken)
    field = system.field  # the springs' scale: the nodal product made, not kept
    assert "_p" not in field.__dict__
    p = field._whitened_nodes()
    assert field.sq_norm() == float(field.d * np.vdot(p, p))  # vdot's own copies


def test_fewer_modes_than_nodes_make_k_g_once(monkeypatch):
    """A dense model morphed on fewer modes than it has degrees of freedom builds K_g
    once: the eigensolver copies the kept matrix and the smooth motions' Rayleigh-Ritz
    step reads it (it was built twice, one a Fortran work copy)."""
    from modalmorph.core import model as model_module

    made = []
    build = model_module.stiffness_matrix
    monkeypatch.setattr(model_module, "stiffness_matrix",
                        lambda *a, **k: made.append(k.get("order", "C")) or build(*a, **k))
    src, dst, pairs = _ellipses(60)
    result = morph(src, dst, matching=pairs, modes=40)
    assert result.shapes.shape[1] == 60 and made == ["C"]  # the source's model's, kept
