"""Reading a URDF or xacro file: its bounds, what is passed to xacro, and each refusal."""

import sys

from dq_fk_ros.description import urdf_reader
from dq_fk_ros.description.urdf_reader import MAX_URDF_BYTES, read_urdf_text
from dq_fk_ros.errors import RobotDescriptionError
import pytest


def refusal(path, **kwargs):
    with pytest.raises(RobotDescriptionError) as caught:
        read_urdf_text(path, **kwargs)
    return str(caught.value)


def test_a_file_of_exactly_the_bound_is_read_whole_and_one_byte_more_is_refused(tmp_path):
    path = tmp_path / 'r.urdf'
    path.write_bytes(b'x' * MAX_URDF_BYTES)
    assert len(read_urdf_text(path)) == MAX_URDF_BYTES
    path.write_bytes(b'x' * (MAX_URDF_BYTES + 1))
    assert refusal(path) == (f'{path}: larger than {MAX_URDF_BYTES // 1024} KiB; a URDF is '
                             f'at most that big')


def test_a_file_that_grows_after_its_size_was_read_is_read_to_the_bound_only(
        tmp_path, monkeypatch):
    path = tmp_path / 'r.urdf'
    path.write_bytes(b'x' * (MAX_URDF_BYTES + 100))
    monkeypatch.setattr(urdf_reader.os.path, 'getsize', lambda _: 10)   # small when asked
    asked = []
    real_open = open

    class Recorder:
        """The file, its ``read(n)`` recording ``n``."""

        def __init__(self, name, mode):
            self.stream = real_open(name, mode)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.stream.close()

        def read(self, size=-1):
            asked.append(size)
            return self.stream.read(size)
    monkeypatch.setattr(urdf_reader, 'open', Recorder, raising=False)
    assert refusal(path).endswith('KiB; a URDF is at most that big')
    assert asked == [MAX_URDF_BYTES + 1]


def test_each_unreadable_file_is_said_in_one_line(tmp_path, monkeypatch):
    path = tmp_path / 'r.urdf'
    path.write_bytes(b'<robot name="\xff"/>')
    assert refusal(path) == f'{path}: not UTF-8 text'

    def denied(*args, **kwargs):
        raise PermissionError(13, 'Permission denied')
    monkeypatch.setattr(urdf_reader, 'open', denied, raising=False)
    assert refusal(path) == f'{path}: cannot be read (Permission denied)'


def test_a_xacro_file_without_xacro_installed_says_how_to_get_it(tmp_path, monkeypatch):
    path = tmp_path / 'r.urdf.xacro'
    path.write_text('<robot name="r"/>')
    monkeypatch.setitem(sys.modules, 'xacro', None)   # import xacro: ImportError
    assert refusal(path) == f'{path}: a .xacro file needs the xacro package (pip install xacro)'


def test_the_xacro_expansion_gets_the_time_limit_roots_and_packages_given(
        tmp_path, monkeypatch):
    path = tmp_path / 'r.urdf.xacro'
    path.write_text('<robot name="r"/>')
    calls = []

    def expand(*args, **kwargs):
        calls.append((args, kwargs))
        return '<robot name="expanded"/>'
    monkeypatch.setattr(urdf_reader, 'expand_xacro', expand)
    stop = object()
    assert read_urdf_text(path, ['/a'], 2.5, stop, {'p': '/p'}, ['/w']) == \
        '<robot name="expanded"/>'
    keywords = {'should_stop': stop, 'packages': {'p': '/p'}, 'within': ['/w']}
    assert calls == [((str(path), ['/a'], 2.5), keywords)]
