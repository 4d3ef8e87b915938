"""dq_fk_node's parameters as one object: the table, the dataclass and the checks agree."""

from dataclasses import fields
import os

from dq_fk_ros.description.shipped import shipped_robots_dir
from dq_fk_ros.errors import ParameterError
from dq_fk_ros.ros.node_parameters import (
    check_values, NODE_PARAMETERS, NodeParameters, ROBOT_PARAMETERS)
import pytest


def test_the_dataclass_has_every_parameter_of_the_table_with_its_default_and_type():
    assert [f.name for f in fields(NodeParameters)] == [p.name for p in NODE_PARAMETERS]
    defaults = NodeParameters()
    for p in NODE_PARAMETERS:
        value = getattr(defaults, p.name)
        assert value == p.default and type(value) is type(p.default), p.name
    assert set(ROBOT_PARAMETERS) <= {p.name for p in NODE_PARAMETERS}


@pytest.mark.parametrize('name, value, says', [
    ('out_of_limits', 'ignore', "out_of_limits is 'ignore'; allowed: warn, clamp, reject"),
    ('joint_states_reliability', 'fast', 'allowed: best_effort, reliable'),
    ('publish_frequency', -1.0, 'publish_frequency must be 0'),
    ('max_publish_rate_hz', 1e7, 'max_publish_rate_hz must be 0'),
    ('max_publish_rate_hz', float('nan'), 'max_publish_rate_hz must be 0'),
    ('urdf_tip_link', 'a b', "urdf_tip_link 'a b' is not a link name"),
    ('urdf_base_link', 'x' * 300, 'urdf_base_link'),
    ('qos_depth', 0, 'qos_depth must be an integer from 1 to 100000, got 0'),
    ('input_batch_ms', float('inf'), 'input_batch_ms must be a number from 0 to 100'),
    ('frame_prefix', 'a\nb/', "frame_prefix 'a?b/' would not give valid frame ids"),
])
def test_a_value_the_node_cannot_use_is_refused_in_one_line(name, value, says):
    for make in (lambda: NodeParameters.from_values({name: value}),
                 lambda: NodeParameters().changed({name: value})):
        with pytest.raises(ParameterError) as error:
            make()
        assert says in str(error.value) and '\n' not in str(error.value)


def test_a_change_makes_a_new_object_and_ignores_other_names():
    old = NodeParameters.from_values({'frame_prefix': 'r1/', 'qos_depth': 5})
    new = old.changed({'frame_prefix': 'r2/', 'use_sim_time': True})
    assert (old.frame_prefix, new.frame_prefix, new.qos_depth) == ('r1/', 'r2/', 5)
    assert new.robot_inputs == {'robot_description_file': '', 'robot_description': '',
                                'urdf_base_link': '', 'urdf_tip_link': ''}
    check_values({'out_of_limits': 'clamp', 'publish_frequency': 0.0})  # allowed: no error


def test_run_time_files_default_to_the_start_files_folder_and_the_shipped_robots(tmp_path):
    robot = tmp_path / 'mine.yaml'
    robot.write_text('name: x\n')
    access = NodeParameters(robot_description_file=str(robot)).file_access(5.0, lambda: False)
    assert access.dirs == (os.path.realpath(tmp_path), shipped_robots_dir())
    assert access.xacro is False
    access = NodeParameters(robot_description_dirs=f'{tmp_path}{os.pathsep}{tmp_path}',
                            allow_runtime_xacro=True).file_access(5.0, lambda: False)
    assert access.dirs == (os.path.realpath(tmp_path), shipped_robots_dir())
    assert access.xacro is True
    with pytest.raises(ParameterError, match='robot_description_dirs: .* is not a folder'):
        NodeParameters(robot_description_dirs=str(robot)).file_access(5.0, lambda: False)
