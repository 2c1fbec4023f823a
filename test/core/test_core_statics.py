"""Tests of assembly and static equilibrium against closed forms and the exact elastica."""

from cbha_inverse.core import chain, links, so3, statics
from cbha_inverse.core.system import EquilibriumSystem
from cbha_inverse.scene import load_scene
import numpy as np
from oracles import chain_forces
from oracles.actuation import oracle
from oracles.loads import actuator_loads
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

E_MOD, NU, R_OUT, R_IN = 2.0e9, 0.35, 0.01, 0.004


def _beam_chain(lengths, base_rotation=None):
    """Return a straight chain of Timoshenko links along +x of the base."""
    comps = [links.timoshenko_compliance(h, E_MOD, NU, R_OUT, R_IN) for h in lengths]
    offsets = [[h, 0.0, 0.0] for h in lengths]
    return chain.ChainModel.from_compliances(comps, offsets, base_rotation=base_rotation)


def test_chaining_reproduces_whole_beam_compliance():
    """The tip compliance of a chain of Timoshenko links equals the whole beam's (1e-9)."""
    lengths = np.array([0.05, 0.03, 0.07, 0.04, 0.06, 0.05])
    base_rot = so3.so3_exp([0.3, -0.7, 1.1])
    model = _beam_chain(lengths, base_rotation=base_rot)
    tangent = chain_forces.assemble_tangent(model, chain.rest_state(model))
    # rest shape: only round-off forces of the stiff axial links (EA/h * eps * length)
    assert np.abs(tangent.internal).max() < 1e-12 * np.abs(tangent.diagonal).max()
    flex = np.linalg.inv(tangent.to_dense())[-6:, -6:]
    rb = np.kron(np.eye(2), base_rot)
    flex_base = rb.T @ flex @ rb          # world axes -> base axes
    ref = links.timoshenko_compliance(lengths.sum(), E_MOD, NU, R_OUT, R_IN)
    np.testing.assert_allclose(flex_base, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_transformed_chain_premultiplies_the_base_pose():
    """``transformed(p, R)``: rest frames ``x -> R x + p``, ``R_i -> R R_i``; links unchanged."""
    lengths = np.array([0.05, 0.03, 0.07])
    comps = [links.timoshenko_compliance(h, E_MOD, NU, R_OUT, R_IN) for h in lengths]
    model = chain.ChainModel.from_compliances(
        comps, [[h, 0.01, 0.0] for h in lengths], rest_rotations=so3.so3_exp(
            [[0.0, 0.1, 0.2], [0.3, 0.0, -0.1], [0.0, 0.0, 0.4]]),
        base_position=[0.1, -0.2, 0.05], base_rotation=so3.so3_exp([0.4, -0.3, 0.2]))
    p, rot = np.array([0.3, 0.7, -0.4]), so3.so3_exp([-0.9, 0.5, 1.3])
    moved = model.transformed(p, rot)
    before, after = chain.rest_state(model), chain.rest_state(moved)
    np.testing.assert_allclose(after.positions, before.positions @ rot.T + p, rtol=0,
                               atol=1e-15)
    np.testing.assert_allclose(after.rotations, rot @ before.rotations, rtol=0, atol=1e-15)
    for name in ('compliances', 'rest_offsets', 'rest_rotations', 'masses'):
        np.testing.assert_array_equal(getattr(moved, name), getattr(model, name))
    with pytest.raises(ValueError, match='proper rotation'):
        model.transformed(p, np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match='position must be finite'):
        model.transformed([0.0, np.nan, 0.0], rot)


def test_warm_start_from_another_base_is_moved_onto_the_model_base():
    """A solution on one base warm-starts the same chain on a moved base: same as cold."""
    lengths = np.full(6, 0.05)
    model = _beam_chain(lengths)
    gravity = [0.0, 0.0, -9.81]
    wrench = np.array([0.0, 0.3, -0.2, 0.0, 0.01, 0.0])
    old = statics.solve_static(model, tip_wrench=wrench, gravity=gravity)
    moved = model.transformed([1e-6, -2e-3, 0.5], so3.so3_exp([0.0, 0.0, 0.3]))
    cold = statics.solve_static(moved, tip_wrench=wrench, gravity=gravity)
    warm = statics.solve_static(moved, tip_wrench=wrench, gravity=gravity,
                                initial_state=old.state)
    assert cold.converged and warm.converged
    np.testing.assert_array_equal(warm.positions[0], moved.base_position)
    np.testing.assert_allclose(warm.positions, cold.positions, rtol=0, atol=1e-9)
    np.testing.assert_allclose(warm.rotations, cold.rotations, rtol=0, atol=1e-9)
    # a one-micrometre shift is seen too (not lost in the tolerance of a converged warm start)
    nudged = model.transformed([1e-6, 0.0, 0.0], np.eye(3))
    again = statics.solve_static(nudged, tip_wrench=wrench, gravity=gravity,
                                 initial_state=old.state)
    np.testing.assert_allclose(again.positions - old.positions, [[1e-6, 0.0, 0.0]] * 7,
                               rtol=0, atol=1e-12)


def test_small_tip_load_is_linear_and_at_rest_nothing_moves():
    """Zero load: rest shape in 0 iterations; tiny tip wrench: displacement = C w (1e-6)."""
    lengths = np.full(8, 0.05)
    model = _beam_chain(lengths)
    res = statics.solve_static(model)
    assert res.converged and res.iterations == 0
    np.testing.assert_allclose(res.positions, chain.rest_state(model).positions, atol=0)
    comp = links.timoshenko_compliance(lengths.sum(), E_MOD, NU, R_OUT, R_IN)
    wrench = 1e-6 / np.sqrt(np.diag(comp)) * np.array([1.0, -0.5, 0.3, 0.2, 0.7, -0.4])
    res = statics.solve_static(model, tip_wrench=wrench)
    assert res.converged and res.iterations <= 3
    disp = np.concatenate([res.positions[-1] - [lengths.sum(), 0, 0],
                           so3.so3_log(res.rotations[-1])])
    np.testing.assert_allclose(disp, comp @ wrench, rtol=1e-5, atol=1e-6 * np.abs(
        comp @ wrench).max())


def _elastica_tip(alpha):
    """Tip (x, y) / L of the inextensible elastica: theta'' + alpha cos(theta) = 0."""
    def shoot(kappa0, dense=False):
        sol = solve_ivp(lambda s, y: [y[1], -alpha * np.cos(y[0]), np.cos(y[0]), np.sin(y[0])],
                        (0.0, 1.0), [0.0, kappa0, 0.0, 0.0], rtol=1e-12, atol=1e-12)
        return sol.y[:, -1]
    kappa0 = brentq(lambda k: shoot(k)[1], 1e-9, alpha, xtol=1e-14)
    return shoot(kappa0)[2:]


def _elastica_chain(n, length=1.0, ei=1.0):
    """Return an effectively inextensible, unshearable Euler-Bernoulli chain."""
    h = length / n
    comp = np.zeros((6, 6))
    comp[0, 0] = h / (1e7 * ei / length ** 2)         # axial: EA = 1e7 EI / L^2
    comp[1, 1] = comp[2, 2] = h ** 3 / (3 * ei)
    comp[3, 3] = h / ei
    comp[4, 4] = comp[5, 5] = h / ei
    comp[1, 5] = comp[5, 1] = h ** 2 / (2 * ei)
    comp[2, 4] = comp[4, 2] = -h ** 2 / (2 * ei)
    return chain.ChainModel.from_compliances(np.repeat(comp[None], n, 0),
                                             np.tile([h, 0.0, 0.0], (n, 1)))


@pytest.mark.parametrize('alpha', [1.0, 2.5, 5.0, 10.0])
def test_large_deflection_matches_elastica(alpha):
    """Dead perpendicular tip load PL^2/EI = alpha: tip deflection within 0.5 % (20 links)."""
    model = _elastica_chain(20)
    res = statics.solve_static(model, tip_wrench=[0.0, alpha, 0.0, 0.0, 0.0, 0.0])
    assert res.converged, res.message
    assert res.iterations <= 8 * res.load_steps
    x_ref, y_ref = _elastica_tip(alpha)
    tip = res.positions[-1]
    assert abs(tip[1] - y_ref) <= 5e-3 * y_ref
    assert abs(tip[0] - x_ref) <= 5e-3 * 1.0
    assert abs(tip[2]) < 1e-12


def test_tip_moment_rolls_chain_into_circle():
    """
    Check that M = 2 pi EI / L closes the chain into a circle, tip rotated by 2 pi.

    The links are identical, so the frames form a regular polygon of 20 sides whose turning angle
    sums to 2 pi: it closes exactly (the link's chord offset under a pure moment rotates every
    side equally). What remains is the Newton stopping error: the residual test bottoms out at
    the round-off floor of the stiff axial links (EA = 1e7 EI / L^2: 64 eps EA/h L ~ 3e-6 N),
    but Newton's last quadratic step lands far below it (~1e-9 L); tolerance 1e-8 L.
    """
    model = _elastica_chain(20)
    res = statics.solve_static(model, tip_wrench=[0.0, 0.0, 0.0, 0.0, 0.0, 2 * np.pi])
    assert res.converged and res.iterations <= 8
    np.testing.assert_allclose(res.positions[-1], 0.0, atol=1e-8)
    angles = so3.so3_log(np.swapaxes(res.rotations[:-1], 1, 2) @ res.rotations[1:])[:, 2]
    assert angles.sum() == pytest.approx(2 * np.pi, abs=1e-8)
    np.testing.assert_allclose(abs(res.quaternions[-1][3]), 1.0, atol=1e-12)
    centre = res.positions[:-1].mean(axis=0)
    radii = np.linalg.norm(res.positions[:-1] - centre, axis=1)
    # vertices of a regular 20-gon whose side is the link chord under M (linear link law):
    # sqrt(h^2 + (C[1,5] M)^2); its circumradius exceeds L / (2 pi) by ~(2 pi / n)^2 / 8
    chord = np.hypot(0.05, model.compliances[0, 1, 5] * 2 * np.pi)
    np.testing.assert_allclose(radii, chord / (2 * np.sin(np.pi / 20)), rtol=1e-7)
    assert radii[0] == pytest.approx(1.0 / (2 * np.pi), rel=(2 * np.pi / 20) ** 2 / 6)


def test_impossible_budget_reports_non_convergence():
    """max_iterations=1 cannot reach PL^2/EI = 10: converged False, a message, strict raises."""
    model = _elastica_chain(20)
    load = [0.0, 10.0, 0.0, 0.0, 0.0, 0.0]
    res = statics.solve_static(model, tip_wrench=load, max_iterations=1, max_load_steps=16)
    assert not res.converged
    assert 'not converged' in res.message
    assert res.load_factor < 1.0 and res.load_steps == 16
    with pytest.raises(statics.StaticConvergenceError) as info:
        statics.solve_static(model, tip_wrench=load, max_iterations=1, max_load_steps=4,
                             strict=True)
    assert not info.value.result.converged


def test_gravity_frame_wrenches_and_load_function_agree():
    """Gravity on lumped masses = the same dead frame forces = a constant load_function."""
    n = 10
    base = _elastica_chain(n, length=0.5, ei=0.2)
    masses = np.linspace(0.01, 0.05, n)
    model = chain.ChainModel.from_compliances(base.compliances, base.rest_offsets, masses=masses)
    g = np.array([0.0, -9.81, -3.0])
    res_g = statics.solve_static(model, gravity=g)
    forces = np.zeros((n, 6))
    forces[:, :3] = masses[:, None] * g
    res_f = statics.solve_static(model, frame_wrenches=forces)
    res_l = statics.solve_static(model, load_function=lambda state: forces)
    for res in (res_g, res_f, res_l):
        assert res.converged, res.message
    np.testing.assert_allclose(res_f.positions, res_g.positions, atol=1e-12)
    np.testing.assert_allclose(res_l.positions, res_g.positions, atol=1e-12)
    # equilibrium of the whole chain: base reaction balances the total weight
    internal = chain_forces.internal_wrenches(model, res_g.state)
    np.testing.assert_allclose(internal[:, :3].sum(axis=0), -masses.sum() * g, atol=1e-10)


def test_follower_moment_matches_dead_moment_in_plane():
    """A follower tip moment about the tip's own z axis equals the dead one in planar bending."""
    model = _elastica_chain(12)

    def follower(state):
        out = np.zeros((12, 6))
        out[-1, 3:] = state.rotations[-1] @ [0.0, 0.0, np.pi]
        return out

    res_f = statics.solve_static(model, load_function=follower)
    res_d = statics.solve_static(model, tip_wrench=[0, 0, 0, 0, 0, np.pi])
    assert res_f.converged and res_d.converged
    np.testing.assert_allclose(res_f.positions, res_d.positions, atol=1e-9)


def test_warm_start_converges_fast_and_falls_back():
    """A nearby previous solution converges in few iterations; a bad one falls back to rest."""
    model = _elastica_chain(20)
    first = statics.solve_static(model, tip_wrench=[0.0, 4.0, 0.0, 0.0, 0.0, 0.0])
    warm = statics.solve_static(model, tip_wrench=[0.0, 4.2, 0.0, 0.0, 0.0, 0.0],
                                initial_state=first.state)
    cold = statics.solve_static(model, tip_wrench=[0.0, 4.2, 0.0, 0.0, 0.0, 0.0])
    assert warm.converged and warm.iterations <= 3 and warm.load_steps == 1
    np.testing.assert_allclose(warm.positions, cold.positions, atol=1e-9)
    curled = statics.solve_static(model, tip_wrench=[0.0, 0.0, 0.0, 0.0, 0.0, 2 * np.pi])
    back = statics.solve_static(model, tip_wrench=[0.0, 4.2, 0.0, 0.0, 0.0, 0.0],
                                initial_state=curled.state, max_iterations=3)
    assert back.converged
    # both pass the residual test, whose floor (round-off of the EA-stiff links, ~3e-6 N) times
    # the bending compliance L^3 / 3EI bounds their difference
    np.testing.assert_allclose(back.positions, cold.positions, atol=1e-6)


def test_assembled_tangent_matches_central_differences():
    """The assembled exact BTD tangent equals central differences of internal_wrenches."""
    lengths = np.array([0.05, 0.03, 0.07, 0.04, 0.06])
    model = _beam_chain(lengths, base_rotation=so3.so3_exp([0.2, 0.1, -0.3]))
    rng = np.random.default_rng(21)
    state = chain.retract(chain.rest_state(model), rng.normal(scale=[2e-3] * 3 + [0.2] * 3,
                                                              size=(5, 6)))
    tangent = chain_forces.assemble_tangent(model, state)
    np.testing.assert_allclose(tangent.internal, chain_forces.internal_wrenches(model, state))
    h = 1e-7
    cols = []
    for e in np.eye(30):
        inc = h * e.reshape(5, 6)
        plus = chain_forces.internal_wrenches(model, chain.retract(state, inc))
        minus = chain_forces.internal_wrenches(model, chain.retract(state, -inc))
        cols.append(-(plus - minus).ravel() / (2 * h))
    fd = np.stack(cols, axis=1)
    exact = tangent.to_dense(exact=True)
    assert np.abs(exact - fd).max() <= 1e-6 * np.abs(fd).max()
    sym = tangent.to_dense()
    np.testing.assert_allclose(sym, sym.T, atol=0)
    np.testing.assert_allclose(sym, 0.5 * (exact + exact.T), atol=1e-12 * np.abs(sym).max())


# Tip positions [m] returned by Scene.forward before the Newton solvers were unified (the
# scene's own solver, retract updates and load continuation), for the cases below.
_FORWARD_TIPS = {
    'tendon_6f_8c': ([6.0, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0],
                     [0.11258033217086617, 0.034862952121425116, 0.006117561215613352]),
    'cbha': ([0.0, 1.5e5, 0.0, 0.0, 0.0, 1.5e5],
             [0.15897876094293845, 0.09088524483254906, 0.09045373501534439]),
}


@pytest.mark.parametrize('name', sorted(_FORWARD_TIPS))
def test_follower_actuation_with_load_tangent_converges(name):
    """
    Cable / pressure loads with their load stiffness: solve_static converges in one load step.

    With the structural tangent alone these cases stalled (load factor 0.40 for the tendon
    trunk, 0.22 for the CBHA after 64 load steps). Independent check: the equilibrium residual
    evaluated with chain_forces.internal_wrenches + gravity + the actuators' loads.
    """
    scene = load_scene(name)
    actuation, tip = (np.asarray(v, dtype=float) for v in _FORWARD_TIPS[name])
    load, tangent = actuator_loads(scene.actuators, actuation)
    res = statics.solve_static(scene.model, gravity=scene.gravity, load_function=load,
                               load_tangent=tangent, strict=True)
    assert res.load_steps == 1 and res.iterations <= 10, res.message
    st = res.state
    applied = oracle(scene.actuators).loads(st.positions, st.rotations, actuation)[1:]
    weight = np.zeros_like(applied)
    weight[:, :3] = scene.model.masses[:, None] * scene.gravity
    residual = chain_forces.internal_wrenches(scene.model, st) + weight + applied
    assert np.abs(residual).max() <= 1e-10 * np.abs(applied).max()
    np.testing.assert_allclose(res.positions[-1], tip, atol=1e-8)
    np.testing.assert_allclose(scene.forward(actuation).positions, res.positions, atol=1e-9)


def test_actuator_load_tangent_matches_central_differences():
    """actuator_loads' tangent (exact, with the cables' skew moment part) = -d loads / dq."""
    scene = load_scene('tendon_6f_8c')
    actuation = np.array([3.0, 1.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.5])
    state = scene.forward(actuation, strict=True).state
    load, tangent = actuator_loads(scene.actuators, actuation)
    n = scene.model.n_links
    h = 1e-6
    cols = []
    for e in np.eye(6 * n):
        inc = h * e.reshape(n, 6)
        plus = load(chain.retract(state, inc))
        minus = load(chain.retract(state, -inc))
        cols.append(-(plus - minus).ravel() / (2 * h))
    fd = np.stack(cols, axis=1)
    exact = tangent(state)
    assert np.abs(exact - fd).max() <= 1e-7 * np.abs(fd).max()
    assert np.abs(fd - fd.T).max() > 1e-5 * np.abs(fd).max()  # the skew part matters


def _material_reference(model, state):
    """Dense ``sum_links Dᵀ K D``, ``D = d delta / d increments`` of each link (paper eq. 8)."""
    n = model.n_links
    out = np.zeros((6 * n + 6, 6 * n + 6))
    for i in range(n):
        r_a, r_b = state.rotations[i], state.rotations[i + 1]
        x_a, x_b = state.positions[i], state.positions[i + 1]
        delta = chain_forces.link_deformation(model.rest_offsets[i], model.rest_rotations[i],
                                              x_a, r_a, x_b, r_b)
        jinv_rt = so3.so3_left_jacobian_inverse(delta[3:]) @ r_a.T
        d = np.zeros((6, 12))
        d[:3, :3], d[:3, 3:6], d[:3, 6:9] = -r_a.T, r_a.T @ so3.hat(x_b - x_a), r_a.T
        d[3:, 3:6], d[3:, 9:] = -jinv_rt, jinv_rt
        out[6 * i:6 * i + 12, 6 * i:6 * i + 12] += d.T @ model.stiffnesses[i] @ d
    return out[6:, 6:]


def test_material_tangent_is_dtkd_and_positive_definite():
    """The fallback tangent equals ``Dᵀ K D`` of the links (dense, per link) and is SPD."""
    model = _elastica_chain(8)
    state = statics.solve_static(model, tip_wrench=[0.0, 6.0, 0.0, 0.0, 0.0, 0.0]).state
    diagonal, upper = chain_forces.material_tangent(model, state)
    dense = chain_forces.blocks_to_dense(diagonal, upper)
    reference = _material_reference(model, state)
    np.testing.assert_allclose(dense, reference, rtol=0, atol=1e-12 * np.abs(reference).max())
    assert np.linalg.eigvalsh(dense).min() > 0.0


@pytest.mark.parametrize('n', [12, 30])
def test_follower_moment_with_its_tangent_rolls_the_circle(n):
    """Follower tip moment 2 pi EI / L with its load stiffness hat(M) (dense and banded LU)."""
    model = _elastica_chain(n, length=1.0, ei=1.0)

    def moment(state):
        return state.rotations[-1] @ [0.0, 0.0, 2 * np.pi]

    def follower(state):
        out = np.zeros((n, 6))
        out[-1, 3:] = moment(state)
        return out

    def tangent(state):
        out = np.zeros((6 * n, 6 * n))
        out[-3:, -3:] = so3.hat(moment(state))
        return out

    res = statics.solve_static(model, load_function=follower, load_tangent=tangent)
    assert res.converged and res.load_steps == 1 and res.iterations <= 8, res.message
    np.testing.assert_allclose(res.positions[-1], res.positions[0], atol=1e-9)


def test_material_fallback_converges_when_the_exact_tangent_fails(monkeypatch):
    """
    A singular exact tangent: modified-Newton steps with the material tangent still converge.

    Every exact step fails as the block LU of a singular tangent does: the compiled step of an
    evaluated point (Newton's ``'direction'`` entry) returns a nonzero info, and the fallback
    chain's exact factor (:meth:`EquilibriumSystem.factor_exact`) none; the material tangent
    alone takes every step.
    """
    model = _elastica_chain(8)
    load = [0.0, 1.0, 0.0, 0.0, 0.0, 0.0]
    methods = []
    steps = statics._Problem.steps

    def counted(self, point, lam):
        for step, method, link_rotation in steps(self, point, lam):
            methods.append(method)
            yield step, method, link_rotation

    monkeypatch.setattr(statics._Problem, 'steps', counted)
    reference = statics.solve_static(model, tip_wrench=load)
    assert set(methods) == {'block_lu'}
    methods.clear()
    monkeypatch.setitem(statics._ENTRIES, 'direction',
                        lambda record, positions, rotations: (1, np.nan))
    monkeypatch.setattr(EquilibriumSystem, 'factor_exact', lambda self: None)
    res = statics.solve_static(model, tip_wrench=load, max_iterations=200)
    assert res.converged, res.message
    assert res.iterations > reference.iterations
    assert 'block_cholesky' in methods and 'block_lu' not in methods
    # linear convergence stops near the round-off floor of the EA-stiff links (as above)
    np.testing.assert_allclose(res.positions, reference.positions, atol=1e-6)
