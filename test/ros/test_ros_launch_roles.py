"""``role:=`` splits each composition between the machines of a cell; ``all`` is their union."""

import re

from cbha_inverse.ros.launch.compositions import ArgumentError, COMPOSITIONS, resolve, ROLES
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
