"""``role:=`` splits each composition between the machines of a cell; ``all`` is their union."""

import re

from cbha_inverse.ros.common.transport import LOOPBACK_UDP_PROFILE
from cbha_inverse.ros.launch.compositions import ArgumentError, COMPOSITIONS, resolve, ROLES
from cbha_inverse.ros.launch.processes import command_lines
import pytest

EXPECTED = {
    ('sim', 'robot'): ['cbha_sim'],
    ('sim', 'control'): ['trajectory', 'inverse_solver'],
    ('sim', 'cameras'): ['stereo_tracker'],
    ('robot', 'robot'): ['robotino_bridge'],
    ('robot', 'control'): ['inverse_solver'],
    ('robot', 'cameras'): ['stereo_tracker'],
}


@pytest.mark.parametrize('name', sorted(COMPOSITIONS))
def test_each_role_starts_its_part_and_all_starts_every_node_once(name):
    composition = COMPOSITIONS[name]

    def nodes(**values):
        return [p.executable for p in resolve(composition, {'feedback': 'stereo', **values})]

    parts = {role: nodes(role=role) for role in ROLES}
    for role in ROLES:
        assert parts[role] == EXPECTED[name, role]
    everything = nodes()
    assert everything == nodes(role='all')
    assert sorted(everything) == sorted(sum(parts.values(), []))
    # the overrides of a node do not depend on the role it is started in
    by_node = {p.executable: p for p in resolve(composition, {'feedback': 'stereo'})}
    for role in ROLES:
        for process in resolve(composition, {'feedback': 'stereo', 'role': role}):
            assert process == by_node[process.executable]


def test_an_unknown_role_is_refused():
    message = 'role:=lab is not one of robot|control|cameras|all'
    with pytest.raises(ArgumentError, match=re.escape(message)):
        resolve(COMPOSITIONS['sim'], {'role': 'lab'})


@pytest.mark.parametrize('name', sorted(COMPOSITIONS))
def test_solver_transport_is_the_solvers_alone(name, tmp_path):
    composition = COMPOSITIONS[name]
    assert all(p.environment == {} for p in resolve(composition, {}))
    processes = resolve(composition, {'solver_transport': 'udp-loopback'})
    environments = {p.executable: p.environment for p in processes}
    solver = environments.pop('inverse_solver')
    assert solver['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SUBNET'
    assert solver['FASTRTPS_DEFAULT_PROFILES_FILE'].endswith(LOOPBACK_UDP_PROFILE)
    assert set(solver) == {'ROS_AUTOMATIC_DISCOVERY_RANGE', 'FASTRTPS_DEFAULT_PROFILES_FILE'}
    assert environments and all(env == {} for env in environments.values())
    # cbha_launch sets them through env(1), for that node alone
    lines = dict(command_lines(processes, tmp_path))
    assert lines['inverse_solver'][:3] == ['env', *(f'{k}={v}' for k, v in solver.items())]
    assert all(argv[0] != 'env' for node, argv in lines.items() if node != 'inverse_solver')
    # loopback only: a controller on a machine of its own would hear no other machine
    for role in ROLES:
        with pytest.raises(ArgumentError, match=re.escape(
                f'it needs every node on this host (role:=all), not role:={role}')):
            resolve(composition, {'solver_transport': 'udp-loopback', 'role': role})
