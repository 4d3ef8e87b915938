"""
Which path computes a chain's poses: the compiled kernel, or numpy (the reference).

The C extension :mod:`dq_fk_ros.kinematics._kernel` (built by setup.py when a C compiler is
there; optional) runs a chain's factor program (:func:`~dq_fk_ros.kinematics.dh_code.
run_program`, the reference) step for step into buffers the caller owns. Without it, or with
``DQ_FK_PURE_PYTHON=1`` in the environment when the package is imported, the numpy path
runs; :func:`kernel_info` says which is active and why. :func:`load_compiled` is how every
optional extension of the package is loaded (the CDR writer of
:mod:`dq_fk_ros.messages.cdr` too), under the same switch.
"""

import importlib
import os

PURE_PYTHON_VARIABLE = 'DQ_FK_PURE_PYTHON'


def load_compiled(module: str, fallback: str = 'python') -> tuple[object, str]:
    """
    Import the optional C extension ``module``: ``(module or None, one line saying why)``.

    None when ``DQ_FK_PURE_PYTHON`` is set (not empty, not 0) or the extension was not
    built (no C compiler at install time): the caller's path named ``fallback`` runs then
    (the line starts with that name; with ``c`` when the extension is loaded).
    """
    if os.environ.get(PURE_PYTHON_VARIABLE, '') not in ('', '0'):
        return None, f'{fallback}: {PURE_PYTHON_VARIABLE}={os.environ[PURE_PYTHON_VARIABLE]}'
    try:
        compiled = importlib.import_module(module)
    except ImportError as exc:
        return None, f'{fallback}: {module} is not built ({exc})'
    return compiled, f'c: compiled ({module})'


KERNEL, _WHY = load_compiled('dq_fk_ros.kinematics._kernel', 'numpy')


def kernel_info() -> dict:
    """Return ``{'active': 'c' or 'numpy', 'why': one line}``: the path FK runs on."""
    return {'active': 'c' if KERNEL is not None else 'numpy', 'why': _WHY}


__all__ = ['KERNEL', 'kernel_info', 'load_compiled', 'PURE_PYTHON_VARIABLE']
