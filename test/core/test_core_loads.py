"""External loads (core.loads): the forward model against closed forms, the inverse under loads."""

from cbha_inverse.core.chain import retract
from cbha_inverse.core.links import cowper_shear_coefficient
from cbha_inverse.core.loads import dead_wrenches, FollowerLoads, Load, Loads
from cbha_inverse.core.so3 import so3_log
from cbha_inverse.scene import load_scene
import numpy as np
import pytest

# the tendon_6f_8c backbone (config/scenes/tendon_6f_8c.yaml): a solid rod of 6 Timoshenko beams
YOUNG, POISSON, RADIUS, LENGTH = 2.0e7, 0.45, 0.006, 0.12
INERTIA, AREA = np.pi * RADIUS ** 4 / 4.0, np.pi * RADIUS ** 2
CBHA_PRESSURES = np.array([6e4, 4e4, 2e4, 3e4, 5e4, 4e4])


@pytest.fixture(scope='module')
def beam():
    """Return the tendon trunk without gravity: a straight cantilever along +x at rest."""
    return load_scene('tendon_6f_8c', gravity=[0.0, 0.0, 0.0])


@pytest.fixture(scope='module')
def cbha():
    return load_scene('cbha')


def _tip(scene, loads, actuation=None):
    """Return the forward result under loads (zero actuation by default)."""
    actuation = np.zeros(len(scene.actuator_names)) if actuation is None else actuation
    return scene.forward(actuation, loads=loads, strict=True)


def test_a_tip_force_deflects_the_cantilever_by_the_timoshenko_closed_form(beam):
    """δ = F L³/(3EI) + F L/(κ G A): Euler-Bernoulli bending plus the beams' shear term."""
    force = 1.0e-3
    rest = _tip(beam, Loads()).effector_positions[-1]
    bent = _tip(beam, Loads((Load.of_wrench('push', 'tip', [0.0, 0.0, -force]),)))
    shear = YOUNG / (2.0 * (1.0 + POISSON)) * AREA * cowper_shear_coefficient(POISSON, RADIUS)
    expected = force * LENGTH ** 3 / (3.0 * YOUNG * INERTIA) + force * LENGTH / shear
    deflection = rest[2] - bent.effector_positions[-1][2]
    assert deflection / LENGTH < 1e-3  # small deflection: the linear closed form applies
    assert deflection == pytest.approx(expected, rel=5e-3)
    # without the shear term the model would be off by more than the tolerance
    assert abs(deflection - force * LENGTH ** 3 / (3.0 * YOUNG * INERTIA)) > 5e-3 * expected


def test_a_tip_torque_turns_the_tip_by_m_l_over_e_i(beam):
    torque = 1.0e-4
    bent = _tip(beam, Loads((Load.of_wrench('twist', 'tip', torque=[0.0, 0.0, torque]),)))
    angle = so3_log(bent.rotations[-1])
    assert angle[2] == pytest.approx(torque * LENGTH / (YOUNG * INERTIA), rel=5e-3)
    np.testing.assert_allclose(angle[:2], 0.0, atol=1e-12)


def test_a_mass_load_equals_its_weight_as_a_base_frame_force():
    scene = load_scene('tendon_6f_8c')
    weight = 0.02 * scene.gravity
    by_mass = _tip(scene, Loads((Load.of_mass('payload', 4, 0.02),)))
    by_force = _tip(scene, Loads((Load.of_wrench('payload', 4, weight),)))
    np.testing.assert_allclose(by_mass.positions, by_force.positions, rtol=0, atol=1e-12)
    unloaded = _tip(scene, Loads())
    assert np.abs(by_mass.positions - unloaded.positions).max() > 1e-4
    np.testing.assert_array_equal(
        dead_wrenches(Loads((Load.of_mass('payload', 4, 0.02),)), 6, scene.gravity)[3, :3],
        weight)


def test_the_follower_tangent_is_the_derivative_of_its_wrenches(beam):
    """``tangent = -d wrenches / dq`` against central differences of the retraction."""
    loads = Loads((Load.of_wrench('thrust', 'tip', [0.3, -0.2, 0.5], [0.01, 0.02, -0.03],
                                  axes='local'),
                   Load.of_wrench('side', 3, [0.0, 0.4, 0.0], axes='local'),
                   Load.of_wrench('dead', 2, [1.0, 0.0, 0.0])))
    followers = FollowerLoads(loads, beam.model.n_links)
    state = _tip(beam, Loads((Load.of_wrench('bend', 'tip', [0.0, 0.05, -0.05],
                                             [0.002, 0.0, 0.0]),))).state
    size, step = 6 * beam.model.n_links, 1e-6
    numeric = np.zeros((size, size))
    for k in range(size):
        increment = np.zeros(size)
        increment[k] = step
        ahead = followers.wrenches(retract(state, increment.reshape(-1, 6)).rotations)
        behind = followers.wrenches(retract(state, -increment.reshape(-1, 6)).rotations)
        numeric[:, k] = -(ahead - behind).reshape(-1) / (2.0 * step)
    np.testing.assert_allclose(followers.tangent(state.rotations), numeric, rtol=0, atol=1e-8)
    assert np.abs(numeric).max() > 0.1


def test_a_follower_load_turns_with_its_frame(beam):
    """
    The equilibrium under a follower load is that of its world wrench at that equilibrium.

    A tip force along the tip's own -z bends the trunk far; applying, as a dead load, the
    wrench the follower has at the converged state gives the same state, while the dead load
    of the force at rest (its direction before the bend) does not.
    """
    local = np.array([0.0, 0.0, -2.0])
    follower = _tip(beam, Loads((Load.of_wrench('thrust', 'tip', local, axes='local'),)))
    assert follower.iterations < 25
    turned = follower.rotations[-1] @ local
    dead = _tip(beam, Loads((Load.of_wrench('thrust', 'tip', turned),)))
    np.testing.assert_allclose(dead.positions, follower.positions, rtol=0, atol=1e-9)
    at_rest = _tip(beam, Loads((Load.of_wrench('thrust', 'tip', local),)))
    assert np.abs(at_rest.positions - follower.positions).max() > 2e-3
    assert np.degrees(np.linalg.norm(so3_log(follower.rotations[-1]))) > 20.0


@pytest.mark.parametrize('build, match', [
    (lambda: Load.of_wrench('f', 'tip', [np.nan, 0.0, 0.0]), 'finite'),
    (lambda: Load.of_wrench('f', 'tip', torque=[0.0, np.inf, 0.0]), 'finite'),
    (lambda: Load.of_wrench('f', 0, [1.0, 0.0, 0.0]), 'base'),
    (lambda: Load.of_wrench('f', 'tip', [1.0, 0.0, 0.0], axes='tool'), 'axes'),
    (lambda: Load.of_mass('m', 'tip', -0.1), 'mass'),
    (lambda: Load.of_mass('m', 'tip', np.nan), 'mass'),
    (lambda: Load('m', 'tip', (1.0, 0, 0, 0, 0, 0), mass=0.1), 'not both'),
    (lambda: Loads((Load.of_mass('m', 1, 0.1), Load.of_mass('m', 2, 0.1))), 'named twice'),
    (lambda: Loads((Load.of_mass('m', 9, 0.1),)).checked(6, (0.0, 0.0, -9.81)), 'outside'),
    (lambda: Loads((Load.of_mass('m', 2, 0.1),)).checked(6, None), 'gravity'),
])
def test_bad_loads_are_refused_with_what_is_wrong(build, match):
    with pytest.raises(ValueError, match=match):
        build()


def test_updated_replaces_a_load_of_the_same_name_and_appends_new_ones():
    loads = Loads((Load.of_mass('a', 1, 0.1), Load.of_mass('b', 2, 0.2)))
    new = loads.updated(Load.of_mass('b', 3, 0.3), Load.of_mass('c', 1, 0.4))
    assert new.names == ('a', 'b', 'c') and new.items[1].frame == 3
    assert new.without('a').names == ('b', 'c') and loads.names == ('a', 'b')


def _settle(solver, target, ticks=60):
    """Run ticks toward a fixed target; return the last actuation."""
    for _ in range(ticks):
        result = solver.step(target[None])
    return result.actuation


def _miss(scene, actuation, target, loads):
    """Return the open-loop distance [m] of the plant's tip from the target."""
    return float(np.linalg.norm(
        scene.forward(actuation, loads=loads, strict=True).effector_positions[-1] - target))


def test_the_inverse_under_a_50_g_payload_reaches_its_targets_open_loop(cbha):
    """
    With the payload in its loads, the solver's actuation puts the loaded plant on target.

    The plant is the nominal scene carrying the same 50 g at the tip: open loop, the misses are
    those of the unloaded solver on the unloaded plant (the model's own convergence), and a
    solver unaware of the payload misses by centimetres.
    """
    payload = Loads((Load.of_mass('payload', 'tip', 0.05),))
    solver = cbha.make_inverse_solver()
    targets = [cbha.forward(CBHA_PRESSURES * f, strict=True).effector_positions[-1]
               for f in (1.0, 0.6, 1.4)]
    misses = {}
    for name, loads in (('unloaded', Loads()), ('loaded', payload)):
        solver.reset()
        solver.set_loads(loads)
        misses[name] = [_miss(cbha, _settle(solver, t), t, loads) for t in targets]
    solver.reset()
    solver.set_loads(Loads())
    unaware = _miss(cbha, _settle(solver, targets[0]), targets[0], payload)
    assert max(misses['unloaded']) < 0.2e-3 and max(misses['loaded']) < 0.2e-3, misses
    assert unaware > 10e-3, unaware


def test_the_inverse_under_a_follower_load_reaches_its_target_open_loop(cbha):
    """A tip force along the tip's own axes: the ticks converge to the loaded equilibrium."""
    loads = Loads((Load.of_wrench('thrust', 'tip', [0.0, 0.3, 0.2], axes='local'),))
    target = cbha.forward(CBHA_PRESSURES, loads=loads, strict=True).effector_positions[-1]
    solver = cbha.make_inverse_solver()
    solver.set_loads(loads)
    actuation = _settle(solver, target, ticks=100)
    assert _miss(cbha, actuation, target, loads) < 0.2e-3
    assert _miss(cbha, actuation, target, Loads()) > 5e-3


def test_unchanged_loads_keep_the_prepared_linearisation(cbha):
    target = cbha.forward(CBHA_PRESSURES, strict=True).effector_positions[-1][None]
    loads = Loads((Load.of_wrench('push', 8, [0.0, 0.1, 0.0]),))
    solver = cbha.make_inverse_solver()
    _settle(solver, target[0], ticks=5)
    solver.set_loads(loads)
    solver.prepare()
    solver.step(target)
    solver.prepare()
    assert solver.set_loads(Loads((Load.of_wrench('push', 8, [0.0, 0.1, 0.0]),))) == loads
    assert solver.step(target).timings['assembly'] == 0.0
    solver.prepare()
    solver.set_loads(Loads())
    assert solver.step(target).timings['assembly'] > 0.0
    with pytest.raises(ValueError, match='outside'):
        solver.set_loads(Loads((Load.of_mass('m', 40, 0.1),)))
