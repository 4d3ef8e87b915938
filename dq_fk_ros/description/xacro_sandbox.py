"""
Expand a ``.xacro`` file in a child process that can read, compute and print, nothing else.

A xacro file is a program: its ``${...}`` expressions and ``$(eval ...)`` substitutions are
Python, and xacro's own check (names of the outer code object only) lets a comprehension
reach ``__subclasses__``; ``$(eval)`` even runs with Python's builtins. So every tool expands
xacro here (:func:`expand_xacro`), in a child process that:

* refuses, before evaluating it, any expression with a name, attribute or string holding
  ``__`` anywhere in it (nested code included: :func:`check_expression`), and evaluates
  with no builtins and without xacro's ``type`` and ``vars`` (their only use here is to
  reach Python's internals through computed names);
* may open files for reading only, and only under ``read_roots`` (the file's package or
  folder, the ROS package paths, the folders the user allowed) and in the packages
  ``$(find)`` finds (:class:`~dq_fk_ros.description.packages.PackageResolver`, also on a
  pip-only install); never for writing. A file is under a root if the file it resolves to
  is, or if its name, made absolute and normalized (``..`` removed as text), is and the
  links keep the file's name: those ``colcon build --symlink-install`` puts in an install
  space (``share/PKG/urdf/x.xacro`` -> ``src/PKG/urdf/x.xacro``) are followed, a name that
  leaves its root as text is not;
* sees an environment cut down to the ROS and locale variables (:data:`ENVIRONMENT`);
* runs under a time limit (wall clock and CPU) and an address-space limit, in a session of
  its own: Ctrl-C reaches the caller, who kills it.

The URDF comes back on the child's stdout (at most :data:`MAX_OUTPUT_BYTES`); a failure is
one line on its stderr.
"""

import ast
from collections.abc import Callable, Mapping, Sequence
import errno
import json
import os
import re
import signal
import subprocess
import sys
import time

from dq_fk_ros.description.packages import python_prefixes

TIME_LIMIT_S = 10.0            # wall clock for one expansion (tools, the node at start-up)
MEMORY_LIMIT_BYTES = 1 << 30   # the child's address space
MAX_OUTPUT_BYTES = 8 << 20     # a URDF is at most this big (as a .urdf file)
# what the child's environment keeps: $(find) and $(optenv ROS_...) work, nothing else leaks
ENVIRONMENT = ('PATH', 'PYTHONPATH', 'AMENT_PREFIX_PATH', 'ROS_PACKAGE_PATH', 'ROS_DISTRO',
               'ROS_VERSION', 'ROS_PYTHON_VERSION', 'LANG', 'LC_ALL', 'LC_CTYPE')
# xacro's names that give a type or an object's namespace: with a computed (string) name
# they reach what check_expression refuses by its spelling
REMOVED_SYMBOLS = ('type', 'vars')


class XacroRefused(Exception):
    """What the child says when it refuses or fails (one line)."""


def check_expression(text: str) -> ast.AST:
    """
    Raise :class:`XacroRefused` if a xacro expression could reach Python's internals.

    Refused: a name, attribute, keyword or string constant containing ``__``, anywhere in
    the expression (lambdas and comprehensions included), and text that is not an
    expression. Checked on the syntax tree, before anything is evaluated.
    """
    try:
        tree = ast.parse(text.strip(), mode='eval')
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        raise XacroRefused(f'not a valid expression: {text[:60]!r}') from None
    for node in ast.walk(tree):
        names = ()
        if isinstance(node, ast.Name):
            names = (node.id,)
        elif isinstance(node, ast.Attribute):
            names = (node.attr,)
        elif isinstance(node, ast.keyword):
            names = (node.arg or '',)
        elif isinstance(node, ast.arg):
            names = (node.arg,)
        elif isinstance(node, ast.Constant) and isinstance(node.value, (str, bytes)):
            value = node.value
            names = (value if isinstance(value, str) else value.decode('latin-1'),)
        for name in names:
            if '__' in name:
                raise XacroRefused(f'expression {text[:60]!r} uses {name[:40]!r}: names with '
                                   f'__ reach Python internals and are not evaluated')
    return tree


# -- the parent's side -------------------------------------------------------------------
def package_root(path: str | os.PathLike) -> str:
    """Return the folder of the nearest ``package.xml`` above ``path``, else its folder."""
    folder = os.path.dirname(os.path.realpath(path))
    at = folder
    while True:
        if os.path.isfile(os.path.join(at, 'package.xml')):
            return at
        up = os.path.dirname(at)
        if up == at:
            return folder
        at = up


def ros_package_roots(environ: Mapping[str, str] | None = None) -> list[str]:
    """
    Return the folders where ``$(find)`` looks.

    Every ament prefix's share, ROS_PACKAGE_PATH, and the shares of this Python's own
    prefixes with an ament index (:func:`~dq_fk_ros.description.packages.python_prefixes`).
    """
    environ = os.environ if environ is None else environ
    roots = [os.path.join(p, 'share') for p in
             environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    roots += [p for p in environ.get('ROS_PACKAGE_PATH', '').split(os.pathsep) if p]
    roots += [os.path.join(p, 'share') for p in python_prefixes()]
    return roots


def default_read_roots(path: str | os.PathLike, extra: Sequence = ()) -> list[str]:
    """Return where a xacro file the user chose may read: its package, ROS packages, ``extra``."""
    return [package_root(path)] + ros_package_roots() + [os.fspath(e) for e in extra]


def expand_xacro(path: str | os.PathLike, read_roots: Sequence[str],
                 time_limit_s: float = TIME_LIMIT_S,
                 memory_limit_bytes: int = MEMORY_LIMIT_BYTES,
                 should_stop: Callable | None = None,
                 packages: Mapping[str, str] | None = None,
                 within: Sequence[str] | None = None) -> str:
    """
    Return the URDF XML of the ``.xacro`` file ``path``, expanded in a confined child process.

    :param read_roots: folders the expansion may read files under (see the module doc).
    :param time_limit_s: the child is killed after this long (wall clock).
    :param should_stop: optional callable; when it returns true the child is killed (a node
        shutting down).
    :param packages: ``{name: folder}`` that ``$(find name)`` gives first (``--package``).
    :param within: folders the search above the file may not leave (a run-time file).
    Raises :class:`XacroRefused` with one line. KeyboardInterrupt and every other exception
    kill the child before they propagate.
    """
    environment = {k: os.environ[k] for k in ENVIRONMENT if k in os.environ}
    request = json.dumps({'path': os.path.abspath(path),  # the child runs in its folder
                          'roots': sorted({form for r in read_roots for form in (
                              os.path.realpath(r), os.path.normpath(os.path.abspath(r)))}),
                          'time_limit_s': time_limit_s, 'memory': memory_limit_bytes,
                          'packages': dict(packages or {}),
                          'within': None if within is None else [os.fspath(w) for w in within]})
    child = subprocess.Popen(
        [sys.executable, '-m', __name__], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, env=environment, close_fds=True, start_new_session=True,
        cwd=os.path.dirname(os.path.abspath(path)))
    try:
        out, err = _communicate(child, request.encode(), time_limit_s, should_stop)
    finally:
        _kill(child)
    if child.returncode != 0:
        text = err.decode('utf-8', 'replace').strip().splitlines()
        if child.returncode < 0 and not text:
            raise XacroRefused(f'xacro was stopped by signal {-child.returncode} (over the '
                               f'{memory_limit_bytes >> 20} MiB memory limit?)')
        raise XacroRefused(text[-1][:500] if text else f'xacro exited with {child.returncode}')
    if len(out) > MAX_OUTPUT_BYTES:
        raise XacroRefused(f'the expanded URDF is larger than {MAX_OUTPUT_BYTES >> 20} MiB')
    try:
        return out.decode('utf-8')
    except UnicodeDecodeError:
        raise XacroRefused('the expanded URDF is not UTF-8') from None


def _communicate(child, request, time_limit_s, should_stop):
    """Send the request and collect the output, in slices so that ``should_stop`` is asked."""
    deadline = time.monotonic() + time_limit_s
    step = 0.1 if should_stop is not None else time_limit_s
    pending = request
    while True:
        try:
            return child.communicate(pending, timeout=max(0.0, min(step, deadline -
                                                                   time.monotonic())))
        except subprocess.TimeoutExpired:
            pending = None
            if time.monotonic() >= deadline:
                raise XacroRefused(f'xacro took longer than {time_limit_s:g} s; stopped '
                                   f'(a macro that expands without end?)') from None
            if should_stop is not None and should_stop():
                raise XacroRefused('xacro stopped: shutting down') from None


def _kill(child):
    """Kill the child's whole session if it is still running, and reap it."""
    if child.poll() is None:
        try:
            os.killpg(child.pid, signal.SIGKILL)
        except OSError:
            child.kill()
    try:
        child.communicate(timeout=5.0)
    except (subprocess.TimeoutExpired, ValueError, OSError):
        pass


# -- the child's side --------------------------------------------------------------------
def _confine(roots, time_limit_s, memory):
    """Limit this process: memory, CPU time, no file writes, reads under ``roots`` only."""
    import builtins
    import io
    import resource
    resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    cpu = int(time_limit_s) + 1
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu))
    resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))
    confined_open, allow = _confined_open(builtins.open, roots)
    builtins.open = io.open = confined_open
    return allow


def _confined_open(real_open, roots):
    """
    Return ``(open, allow)``: ``open`` reads files under ``roots`` only; ``allow`` adds one.

    The child puts it in place of ``builtins.open``; the tests call it in their own process
    (test_xacro_child.py), where mutation testing sees it.
    """
    from dq_fk_ros.description.symlinks import follow_keeping_names
    roots = [r.rstrip(os.sep) + os.sep for r in roots]

    def allow(folder):
        for form in (os.path.realpath(folder), os.path.normpath(os.path.abspath(folder))):
            roots.append(form.rstrip(os.sep) + os.sep)

    def confined_open(file, mode='r', *args, **kwargs):
        # (errno, strerror and filename all set: xacro builds its message from the last two)
        if not isinstance(file, (str, bytes, os.PathLike)):
            raise PermissionError(errno.EACCES, 'xacro may open only files by name', '?')
        shown = os.fsdecode(file)[:200]
        if any(c in str(mode) for c in 'wax+'):
            raise PermissionError(errno.EACCES, 'refused, xacro may not write files', shown)
        named = os.path.normpath(os.path.abspath(os.fsdecode(file)))
        path = os.path.realpath(named)
        # under a root as resolved, or as named when every link on the way keeps its name
        # (those a --symlink-install build makes: share/PKG/urdf/x.xacro ->
        # src/PKG/urdf/x.xacro; description/symlinks.py)
        if not any(path.startswith(root) for root in roots):
            found = [follow_keeping_names(root, named) for root in roots
                     if named.startswith(root)]
            path = next((f for f in found if f is not None), None)
            if path is None:
                raise PermissionError(errno.EACCES, "refused, outside the robot's package and "
                                      'the allowed folders (--package, read_roots)', shown)
        return real_open(path, mode, *args, **kwargs)

    return confined_open, allow


def _patch_xacro(resolver, allow):
    """
    Make xacro evaluate through :func:`check_expression`, with no builtins.

    ``$(find)`` asks ``resolver``; the folder found may then be read (``allow``).
    """
    import xacro
    import xacro.substitution_args as substitution
    from dq_fk_ros.description.packages import PackageNotFound

    def find(name):
        try:
            folder = resolver.find(name)
        except PackageNotFound as exc:
            raise substitution.SubstitutionException(str(exc)) from None
        allow(folder)
        return folder

    def safe_eval(expr, symbols, local=None):
        check_expression(expr)
        code = compile(expr.strip(), '<expression>', 'eval')
        symbols.update(__builtins__={})
        return eval(code, symbols, local)

    # xacro's own parts the sandbox replaces or calls (private to xacro: pinned in
    # requirements, and test_xacro_sandbox.py fails if one is missing)
    eval_arg, eval_dict, names_of = (substitution._eval_arg, substitution._eval_dict,
                                     substitution._DictWrapper)

    def eval_substitution(text, context):
        check_expression(text)
        arguments = dict(context.get('arg', {}))
        names = {'arg': lambda name: substitution.convert_value(
            eval_arg(name, args=arguments), 'auto')}
        names.update({k: v for k, v in eval_dict.items() if k != '__builtins__'})
        code = compile(text.strip(), '<$(eval)>', 'eval')
        return str(eval(code, {'__builtins__': {}}, names_of(arguments, names)))

    xacro.safe_eval = safe_eval
    substitution._eval = eval_substitution
    substitution._eval_find = find
    eval_dict['find'] = find
    symbols = xacro._global_symbols
    for table in (symbols, symbols['python']):
        for name in REMOVED_SYMBOLS:
            table.pop(name, None)
    return xacro


def _expand(request, confine=_confine):
    """
    Return the URDF (bytes) a request asks for; raise :class:`XacroRefused` with one line.

    ``confine(roots, time_limit_s, memory)`` limits the process and returns ``allow`` (the
    tests, calling this in their own process, give one that limits nothing).
    """
    try:
        from dq_fk_ros.description.packages import PackageResolver
        allow = confine(request['roots'], request['time_limit_s'], request['memory'])
        resolver = PackageResolver(request['packages'], near=request['path'],
                                   within=request['within'])
        xacro = _patch_xacro(resolver, allow)
        xacro.verbosity = 0  # its warnings would go to stderr, where the error line goes
        text = xacro.process_file(request['path']).toxml()
    except MemoryError:
        raise XacroRefused(f'xacro ran out of its {request["memory"] >> 20} MiB memory '
                           'limit') from None
    except RecursionError:
        raise XacroRefused('xacro nested too deeply (macros or expressions)') from None
    except Exception as exc:  # xacro raises many kinds; one line for the user
        raise XacroRefused(_one_line(exc)) from None
    data = text.encode('utf-8')
    if len(data) > MAX_OUTPUT_BYTES:
        raise XacroRefused(f'the expanded URDF is larger than {MAX_OUTPUT_BYTES >> 20} MiB')
    return data


def _child_main():
    request = json.loads(sys.stdin.read(1 << 20))
    try:
        data = _expand(request)
    except XacroRefused as exc:
        sys.stderr.write(f'{exc}\n')
        return 1
    sys.stdout.buffer.write(data)
    return 0


def _one_line(exc):
    """Return xacro's message in one line, without ``<class '...'>:`` and the repeat after."""
    lines = [line.strip() for line in str(exc)[:2000].splitlines() if line.strip()]
    text = ' '.join(lines) if lines else type(exc).__name__
    text = re.sub(r"<class '[\w.]+'>: ", '', text)
    text = re.sub(r'(?<=\S) \[Errno \d+\] .*$', '', text)  # the OSError said again
    for cut in range(len(text) // 2, 0, -1):  # "A A rest": say A once
        first = text[:cut]
        if text[cut + 1:].startswith(first) and text[cut] == ' ':
            text = first + text[cut + 1 + len(first):]
            break
    text = ''.join(c if c.isprintable() else '?' for c in text)
    return text[:400]


__all__ = ['check_expression', 'default_read_roots', 'expand_xacro', 'package_root',
           'ros_package_roots', 'XacroRefused']

if __name__ == '__main__':
    sys.exit(_child_main())
