"""The ``dq_fk`` command line, run in-process through its ``main``."""

import json

from dq_fk_ros.cli.dq_fk import main
from dq_fk_ros.description.shipped import shipped_robot_path
import numpy as np
import pytest
from vendor_urdfs import robots_dir


def run(capsys, *argv):
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def test_fk_table_shows_the_rl15_end_effector(capsys):
    rc, out, _ = run(capsys, 'fk', 'rl15')
    assert rc == 0
    last = out.strip().splitlines()[-1].split()
    assert last[:3] == ['eeCarry_seg6', 'wrist_seg5', 'yes']  # a DH file's frame: on TF
    assert [float(v) for v in last[3:10]] == pytest.approx(
        [1.025, 0.0, 1.445, 0.707107, 0.0, 0.707107, 0.0], abs=1e-6)


def test_fk_says_poses_are_absolute_beside_the_tf_parent(capsys):
    """The parent column is TF's parent; the pose beside it is in the fixed frame."""
    rc, out, _ = run(capsys, 'fk', 'rl15', '--joints', '0.3', '0', '0', '0', '0', '0')
    comment, header, *_ = out.splitlines()
    assert 'every pose is in world, not relative to its tf_parent' in comment
    assert header.split()[:2] == ['frame', 'tf_parent']
    rc, out, _ = run(capsys, 'fk', 'rl15', '--json')
    assert json.loads(out)['frames'][-1]['tf_parent'] == 'wrist_seg5'


def test_fk_json_with_named_joints_in_degrees(capsys):
    rc, out, _ = run(capsys, 'fk', 'rl15', '--json', '--deg', '--joints', 'joint_1=90',
                     '--matrix')
    assert rc == 0
    data = json.loads(out)
    assert data['joints']['joint_1'] == pytest.approx(1.5707963267948966)
    ee = data['frames'][-1]
    # joint 1 turns the arm by 90 deg about the vertical: x -> y
    assert ee['position'] == pytest.approx([0.0, 1.025, 1.445], abs=1e-12)
    assert len(ee['matrix']) == 4 and 'rpy' not in ee


def test_fk_positional_values_in_radians(capsys):
    rc, out, _ = run(capsys, 'fk', 'config/rrc.yaml', '--json', '--joints', '0', '0', '0',
                     '0.1')
    assert rc == 0
    assert json.loads(out)['frames'][-1]['position'] == pytest.approx([0.7, 0, -0.1])


@pytest.mark.parametrize('argv, words', [
    (['fk', 'rl15', '--joints', '1', '2'], ['has 6 joints', 'got 2 values']),
    (['fk', 'rl15', '--joints', 'elbow=1'], ["unknown joint 'elbow'", 'joint_1']),
    (['fk', 'rl15', '--joints', 'joint_1=1', '2'], ['not a mix']),
    (['fk', 'rl15', '--joints', 'joint_1=abc'], ["value of joint_1 is 'abc'"]),
    (['fk', 'rl15', '--joints', 'joint_1=nan'], ['must be finite']),
    (['fk', 'no_such_robot'], ['no_such_robot: no such file']),
])
def test_fk_user_errors_are_one_line_and_exit_1(capsys, argv, words):
    rc, out, err = run(capsys, *argv)
    assert rc == 1 and out == ''
    assert err.count('\n') == 1 and err.startswith('dq_fk: ')
    for word in words:
        assert word in err


def test_out_of_limits_warns(capsys):
    rc, _, err = run(capsys, 'fk', 'puma560', '--deg', '--joints', 'q2=300')
    assert rc == 0 and 'q2 = 5.23599 is outside its limits' in err


def test_validate_reports_every_bad_file_and_fails(capsys, tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('robot: x\nbase: {frame: b}\nchain:\n  - {frame: l, joint: j, theta: 0, '
                   'd: 0, a: 0, alfa: 0}\n')
    rc, out, err = run(capsys, 'validate', 'rl15', str(bad))
    assert rc == 1
    assert 'rl15.yaml: ok (rl15, standard DH, 6 rows, 6 joints, 7 frames)' in out
    assert f"{bad}: chain[0] (frame 'l'): unknown field 'alfa'" in err


def test_list_names_the_shipped_robots(capsys):
    rc, out, _ = run(capsys, 'list')
    assert rc == 0 and 'rl15' in out and 'panda' in out


def test_urdf_to_file(capsys, tmp_path):
    target = tmp_path / 'rl15.urdf'
    rc, _, err = run(capsys, 'urdf', 'rl15', '-o', str(target))
    assert rc == 0 and 'wrote' in err
    assert target.read_text().startswith('<?xml')


def test_a_joint_given_twice_is_refused(capsys):
    rc, out, err = run(capsys, 'fk', 'rl15', '--joints', 'joint_1=1', 'joint_1=2')
    assert rc == 1 and out == ''
    assert err == 'dq_fk: --joints: joint_1 is given twice (1 and 2); give each joint once\n'


def test_validate_of_files_that_crashed_it_is_one_line_each(capsys, tmp_path):
    """A 400-digit integer and deep nesting gave tracebacks (OverflowError, RecursionError)."""
    text = open(shipped_robot_path('rl15'), encoding='utf-8').read()
    huge, deep = tmp_path / 'huge.yaml', tmp_path / 'deep.yaml'
    huge.write_text(text.replace('a: 200', 'a: ' + '9' * 400, 1))
    deep.write_text(text.replace('a: 200', 'a: ' + '[' * 5000 + ']' * 5000, 1))
    rc, out, err = run(capsys, 'validate', str(huge), str(deep), 'rl15')
    assert rc == 1 and out.count('ok (rl15') == 1
    assert err.splitlines() == [
        f"{huge}: chain[0] (frame 'shoulder_seg1'): field 'a' must be a finite number, "
        f'got an integer of 400 digits',
        f'{deep}: YAML nested too deeply to be a robot description']


@pytest.mark.parametrize('robot', ['rl15', 'dual_arm'])
def test_fk_code_prints_the_code_the_node_runs(robot, capsys):
    from dq_fk_ros.description.schema import load_robot_description
    assert main(['fk', robot, '--code']) == 0
    source = capsys.readouterr().out
    assert source.startswith('def frame_poses(q):')
    model = load_robot_description(shipped_robot_path(robot))
    namespace = {}
    code = model.kinematics.unrolled if model.branches else model.chain.frame_poses_code
    exec(compile(source, 'printed', 'exec'), code.__globals__, namespace)
    q = np.linspace(-0.5, 0.5, model.dof).tolist()
    assert namespace['frame_poses'](q) == model.frame_poses(q)  # the same function, printed


def test_a_floating_root_urdf_validates_and_fk_marks_what_is_on_tf(capsys, tmp_path):
    """solo12 under a floating joint: "no moving joint below world", 0 links, said ok."""
    text = open(f'{robots_dir()}/solo_description/robots/solo12.urdf').read()
    at = text.index('<link')
    path = tmp_path / 'solo12_floating.urdf'
    path.write_text(text[:at] + '<link name="world"/><joint name="root" type="floating">'
                    '<parent link="world"/><child link="base_link"/></joint>' + text[at:])
    rc, out, _ = run(capsys, 'validate', str(path))
    assert rc == 0 and '12 joints' in out, out
    rc, out, _ = run(capsys, 'fk', str(path), '--json')
    frames = {f['frame']: f['on_tf'] for f in json.loads(out)['frames']}
    assert frames['base_link'] == 'root' and frames['FL_FOOT'] == 'yes'
    assert {name for name, on in frames.items() if on == 'yes'} == {
        f'{leg}_{part}' for leg in ('FL', 'FR', 'HL', 'HR')
        for part in ('SHOULDER', 'UPPER_LEG', 'LOWER_LEG', 'FOOT')}
    rc, out, _ = run(capsys, 'fk', str(path), '--dh-frames')
    assert rc == 0 and any(line.split()[:3] == ['dh0', 'world', 'yes']
                           for line in out.splitlines())
