"""
Which path computes a chain's poses: the compiled kernel, or numpy (the reference).

The C extension :mod:`dq_fk_ros.kinematics._kernel` (built by setup.py when a C compiler is
there; optional) runs a chain's factor program (:func:`~dq_fk_ros.kinematics.dh_code.
run_program`, the reference) step for step into buffers the caller owns. Without it, or with
``DQ_FK_PURE_PYTHON=1`` in the environment when the package is imported, the numpy path
runs; :func:`kernel_info` says which is active and why.
"""

import os

PURE_PYTHON_VARIABLE = 'DQ_FK_PURE_PYTHON'


def _load():
    if os.environ.get(PURE_PYTHON_VARIABLE, '') not in ('', '0'):
        return None, f'numpy: {PURE_PYTHON_VARIABLE}={os.environ[PURE_PYTHON_VARIABLE]}'
    try:
        from dq_fk_ros.kinematics import _kernel
    except ImportError as exc:
        return None, f'numpy: the C kernel is not built ({exc})'
    return _kernel, 'c: the compiled kernel (dq_fk_ros.kinematics._kernel)'


KERNEL, _WHY = _load()


def kernel_info() -> dict:
    """Return ``{'active': 'c' or 'numpy', 'why': one line}``: the path FK runs on."""
    return {'active': 'c' if KERNEL is not None else 'numpy', 'why': _WHY}


__all__ = ['KERNEL', 'kernel_info', 'PURE_PYTHON_VARIABLE']
