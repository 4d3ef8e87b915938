"""
The xacro sandbox's child code, run in this process: mutation testing judges only that.

The child process runs the same functions confined (test_xacro_sandbox.py); here each is
called directly: ``_confined_open`` without replacing ``open``, ``_expand`` with a
``confine`` that limits nothing, xacro's patches undone after each test.
"""

import errno
import os

from dq_fk_ros.description import xacro_sandbox
from dq_fk_ros.description.xacro_sandbox import (
    _confined_open, _expand, _one_line, _patch_xacro, REMOVED_SYMBOLS, XacroRefused)
import pytest
from xacro_texts import ESCAPES, escapes, HEAD, link, TAIL, write


def test_xacros_message_is_made_one_printable_line_said_once():
    """The child's _one_line, run here: xacro's own texts as the sandbox passes them on."""
    assert _one_line(ValueError('line one\n\n   line two  \n')) == 'line one line two'
    assert _one_line(ValueError('')) == 'ValueError'
    assert _one_line(ValueError("<class 'xacro.XacroException'>: no such macro")) == \
        'no such macro'
    assert _one_line(OSError("cannot open x.xacro [Errno 2] No such file: 'x.xacro'")) == \
        'cannot open x.xacro'
    assert _one_line(ValueError('[Errno 2] alone')) == '[Errno 2] alone'   # nothing said before
    assert _one_line(ValueError('bad macro bad macro in arm.xacro')) == 'bad macro in arm.xacro'
    assert _one_line(ValueError('a a')) == 'a'
    assert _one_line(ValueError('abab')) == 'abab'   # a repeat without the space between
    assert _one_line(ValueError('tab\there\x1b[31m')) == 'tab?here?[31m'
    assert _one_line(ValueError('x' * 5000)) == 'x' * 400
    long_first = 'y' * 2500 + '\nsecond line'
    assert _one_line(ValueError(long_first)) == 'y' * 400   # (2000 read: the repeat search)


@pytest.fixture
def xacro_restored(monkeypatch):
    """Undo after the test what the child's code changes in xacro (patches, verbosity)."""
    import xacro
    import xacro.substitution_args as substitution
    monkeypatch.setattr(xacro, 'safe_eval', xacro.safe_eval)
    monkeypatch.setattr(xacro, 'verbosity', xacro.verbosity)
    monkeypatch.setattr(substitution, '_eval', substitution._eval)
    monkeypatch.setattr(substitution, '_eval_find', substitution._eval_find)
    monkeypatch.setitem(substitution._eval_dict, 'find', substitution._eval_dict['find'])
    for table in (xacro._global_symbols, xacro._global_symbols['python']):
        for name in REMOVED_SYMBOLS:
            if name in table:
                monkeypatch.setitem(table, name, table[name])
    return xacro


@pytest.fixture
def patched_xacro(xacro_restored):
    """Patch xacro in this process as the child does; every change is undone after."""
    allowed = []

    class Resolver:
        def find(self, name):
            if name != 'arm':
                from dq_fk_ros.description.packages import PackageNotFound
                raise PackageNotFound(f'package {name!r} not found')
            return '/packages/arm'
    return _patch_xacro(Resolver(), allowed.append), allowed


@pytest.mark.parametrize('name', ESCAPES)
def test_the_patched_xacro_refuses_each_escape_in_this_process(tmp_path, name, patched_xacro):
    xacro, _ = patched_xacro
    marker = tmp_path / 'marker'
    path = write(tmp_path, 'evil.xacro', escapes(marker)[name])
    with pytest.raises(Exception):
        xacro.process_file(str(path))
    assert not marker.exists()


def test_the_patched_xacro_evaluates_ordinary_xacro_and_finds_through_the_resolver(
        tmp_path, patched_xacro):
    xacro, allowed = patched_xacro
    body = ('<xacro:property name="l" value="0.5"/><xacro:arg name="n" default="3"/>'
            '<link name="a_${l * 2}_$(eval 2 * 3)_$(eval n * 2)_$(find arm)"/>')
    path = write(tmp_path, 'ok.xacro', HEAD + body + TAIL)
    names = [e.getAttribute('name') for e in
             xacro.process_file(str(path)).getElementsByTagName('link')]
    assert names == ['a_1.0_6_6_/packages/arm']   # an argument (3) by its name in $(eval)
    body = ('<xacro:macro name="m" params="w"><link name="m_${w * 2}"/></xacro:macro>'
            '<xacro:m w="3"/>')
    path = write(tmp_path, 'macro.xacro', HEAD + body + TAIL)
    assert [e.getAttribute('name') for e in   # a macro's parameters: xacro's local symbols
            xacro.process_file(str(path)).getElementsByTagName('link')] == ['m_6']
    # (xacro 2.1.1 ends $(...) at its first ')': arg('n') cannot be written in $(eval))
    path = write(tmp_path, 'no_args.xacro', HEAD + '<link name="$(eval 1 + 1)"/>' + TAIL)
    assert [e.getAttribute('name') for e in
            xacro.process_file(str(path)).getElementsByTagName('link')] == ['2']
    assert allowed == ['/packages/arm']   # the folder found may be read
    path = write(tmp_path, 'lost.xacro', HEAD + '<link name="$(find nowhere)"/>' + TAIL)
    with pytest.raises(Exception, match="package 'nowhere' not found"):
        xacro.process_file(str(path))
    for expression in ('${python.type(1)}', '${python.vars()}', '${vars()}', '${type(1)}'):
        path = write(tmp_path, 'gone.xacro', link(expression))
        with pytest.raises(Exception):
            xacro.process_file(str(path))
    path = write(tmp_path, 'builtins.xacro', link('${open}'))
    with pytest.raises(Exception, match='open'):   # no builtins beyond xacro's own list
        xacro.process_file(str(path))


class Opened:
    """A stand-in for ``open``: records each call and returns the path it was given."""

    def __init__(self):
        self.calls = []

    def __call__(self, path, *args, **kwargs):
        self.calls.append((path, args, kwargs))
        return path


def test_the_confined_open_reads_under_its_roots_and_what_is_allowed_after(tmp_path):
    package, other = tmp_path / 'pkg', tmp_path / 'pkg2'   # a root is a folder, not a prefix
    for folder in (package, other):
        folder.mkdir()
        write(folder, 'a.xacro', HEAD + TAIL)
    real_open = Opened()
    confined, allow = _confined_open(real_open, [str(package) + os.sep])   # one / kept
    assert confined(str(package / 'a.xacro')) == str(package / 'a.xacro')
    assert confined(os.fsencode(package / 'a.xacro'), 'rb', 4096, encoding=None) == \
        str(package / 'a.xacro')   # bytes and path-likes; arguments passed on
    assert confined(package / 'sub' / '..' / 'a.xacro', buffering=-1) == \
        str(package / 'a.xacro')
    assert real_open.calls[1:] == [(str(package / 'a.xacro'), ('rb', 4096), {'encoding': None}),
                                   (str(package / 'a.xacro'), ('r',), {'buffering': -1})]
    for name in (other / 'a.xacro', package / '..' / 'pkg2' / 'a.xacro'):
        with pytest.raises(PermissionError) as refused:
            confined(str(name))
        assert (refused.value.errno, refused.value.strerror, refused.value.filename) == (
            errno.EACCES, "refused, outside the robot's package and the allowed folders "
            '(--package, read_roots)', str(name))
    allow(str(other / '.' / ''))   # $(find) found it
    assert confined(str(other / 'a.xacro')) == str(other / 'a.xacro')
    assert len(real_open.calls) == 4


def test_a_folder_allowed_is_that_folder_whatever_its_name_ends_with(tmp_path):
    """A folder named 'pkg ' (a trailing space) allows 'pkg /...', never its neighbour 'pkg/'."""
    spaced, plain = tmp_path / 'pkg ', tmp_path / 'pkg'
    for folder in (spaced, plain):
        folder.mkdir()
        write(folder, 'a.xacro', HEAD + TAIL)
    confined, allow = _confined_open(Opened(), [str(tmp_path / 'elsewhere')])
    allow(str(spaced))
    assert confined(str(spaced / 'a.xacro')) == str(spaced / 'a.xacro')
    with pytest.raises(PermissionError):
        confined(str(plain / 'a.xacro'))


def test_the_confined_open_never_writes_and_opens_only_names(tmp_path):
    real_open = Opened()
    confined, _ = _confined_open(real_open, [str(tmp_path)])
    long_name = str(tmp_path / ('w' * 300))
    for mode in ('w', 'a', 'x', 'r+', 'wb', 'rb+', 'ab'):
        with pytest.raises(PermissionError) as refused:
            confined(long_name, mode)
        assert (refused.value.errno, refused.value.strerror, refused.value.filename) == (
            errno.EACCES, 'refused, xacro may not write files', long_name[:200]), mode
    with pytest.raises(PermissionError) as refused:
        confined(str(tmp_path / 'x.xacro'), mode='w')   # the mode given by name
    for descriptor in (0, 3, None):
        with pytest.raises(PermissionError) as refused:
            confined(descriptor)
        assert (refused.value.errno, refused.value.strerror, refused.value.filename) == (
            errno.EACCES, 'xacro may open only files by name', '?')
    assert real_open.calls == []
    outside = '/' + 'o' * 300
    with pytest.raises(PermissionError) as refused:
        confined(outside)
    assert refused.value.filename == outside[:200]


def test_the_confined_open_follows_links_that_keep_their_names_only(tmp_path):
    clone, package = tmp_path / 'clones' / 'pkg', tmp_path / 'ws' / 'pkg'
    clone.mkdir(parents=True)
    package.parent.mkdir()
    write(clone, 'part.xacro', HEAD + TAIL)
    write(clone, 'secret.yaml', 'password: hunter2\n')
    os.symlink(clone, package)   # src/pkg -> a clone named pkg: followed
    os.symlink(clone / 'secret.yaml', clone / 'renamed.xacro')   # another name: not
    real_open = Opened()
    confined, _ = _confined_open(real_open, [str(package)])
    assert confined(str(package / 'part.xacro')) == str(clone / 'part.xacro')
    with pytest.raises(PermissionError, match='outside'):
        confined(str(package / 'renamed.xacro'))
    # the root as resolved holds the file too: opened by the resolved name
    confined, _ = _confined_open(real_open, [str(clone)])
    assert confined(str(package / 'part.xacro')) == str(clone / 'part.xacro')
    assert len(real_open.calls) == 2


def request(path, roots=(), **fields):
    """Return the request :func:`expand_xacro` sends, for ``path``."""
    return dict({'path': str(path), 'roots': [str(r) for r in roots], 'time_limit_s': 7.5,
                 'memory': 3 << 20, 'packages': {}, 'within': None}, **fields)


class Confine:
    """A ``confine`` that limits nothing: records its arguments and what it is told to allow."""

    def __init__(self, error=None):
        self.calls, self.allowed, self.error = [], [], error

    def __call__(self, roots, time_limit_s, memory):
        self.calls.append((roots, time_limit_s, memory))
        if self.error is not None:
            raise self.error
        return self.allowed.append


def test_expand_returns_the_urdf_confined_as_asked_and_finds_given_packages(
        tmp_path, xacro_restored):
    arm = tmp_path / 'arm'
    arm.mkdir()
    path = write(tmp_path, 'r.urdf.xacro', HEAD + '<link name="a$(find arm)"/>' + TAIL)
    confine = Confine()
    out = _expand(request(path, [tmp_path], packages={'arm': str(arm)}), confine)
    assert isinstance(out, bytes) and f'<link name="a{arm}"/>'.encode() in out
    assert confine.calls == [([str(tmp_path)], 7.5, 3 << 20)]
    assert confine.allowed == [str(arm)]
    assert xacro_restored.verbosity == 0   # xacro's warnings would be taken for the error


def test_expand_looks_for_packages_above_the_file_but_not_out_of_within(
        tmp_path, xacro_restored):
    package = tmp_path / 'up' / 'arm'
    (package / 'urdf').mkdir(parents=True)
    (package / 'package.xml').write_text('<package><name>arm</name></package>')
    path = write(package / 'urdf', 'r.urdf.xacro', HEAD + '<link name="$(find arm)"/>' + TAIL)
    out = _expand(request(path), Confine())
    assert f'<link name="{package}"/>'.encode() in out
    with pytest.raises(XacroRefused, match='arm'):
        _expand(request(path, within=[str(package / 'urdf')]), Confine())


@pytest.mark.parametrize('error, said', [
    (MemoryError(), 'xacro ran out of its 3 MiB memory limit'),
    (RecursionError(), 'xacro nested too deeply (macros or expressions)'),
    (ValueError("<class 'x.Y'>: bad bad"), 'bad'),
])
def test_expand_says_each_failure_in_one_line(tmp_path, error, said, xacro_restored):
    path = write(tmp_path, 'r.urdf.xacro', HEAD + TAIL)
    with pytest.raises(XacroRefused) as refused:
        _expand(request(path), Confine(error))
    assert str(refused.value) == said
    assert refused.value.__cause__ is None and refused.value.__suppress_context__


def test_expand_refuses_what_xacro_refuses_and_an_output_over_the_bound(
        tmp_path, xacro_restored, monkeypatch):
    marker = tmp_path / 'marker'
    path = write(tmp_path, 'evil.xacro', escapes(marker)['globals'])
    with pytest.raises(XacroRefused, match='__'):
        _expand(request(path, [tmp_path]), Confine())
    assert not marker.exists()
    path = write(tmp_path, 'loop.xacro', HEAD + '<xacro:macro name="m"><xacro:m/></xacro:macro>'
                 '<xacro:m/>' + TAIL)
    with pytest.raises(XacroRefused, match='^xacro nested too deeply'):
        _expand(request(path), Confine())
    monkeypatch.setattr(xacro_sandbox, 'MAX_OUTPUT_BYTES', 1 << 20)
    overhead = len(_expand(request(write(tmp_path, 'big.xacro', link('x'))), Confine())) - 1
    path = write(tmp_path, 'big.xacro', link('x' * ((1 << 20) - overhead)))
    assert len(_expand(request(path), Confine())) == 1 << 20   # at the bound: passed
    path = write(tmp_path, 'big.xacro', link('x' * ((1 << 20) - overhead + 1)))
    with pytest.raises(XacroRefused) as refused:
        _expand(request(path), Confine())
    assert str(refused.value) == 'the expanded URDF is larger than 1 MiB'


def test_eval_has_xacros_names_and_no_builtins(tmp_path, patched_xacro):
    """``$(eval)`` knows xacro's names (math, true) but no builtin; it cannot call at all."""
    xacro, _ = patched_xacro
    body = '<link name="$(eval round(pi, 2))"/>'   # xacro 2.1.1 cuts the text at ')'
    path = write(tmp_path, 'call.xacro', HEAD + body + TAIL)
    with pytest.raises(Exception, match='not a valid expression'):
        xacro.process_file(str(path))
    body = '<link name="$(eval pi * 2)"/><link name="$(eval true)"/><link name="$(eval e > 2)"/>'
    path = write(tmp_path, 'names.xacro', HEAD + body + TAIL)
    names = [e.getAttribute('name') for e in
             xacro.process_file(str(path)).getElementsByTagName('link')]
    assert names == [str(3.141592653589793 * 2), 'True', 'True']
    path = write(tmp_path, 'open.xacro', HEAD + '<link name="$(eval open)"/>' + TAIL)
    with pytest.raises(Exception, match="name 'open' is not defined"):
        xacro.process_file(str(path))
