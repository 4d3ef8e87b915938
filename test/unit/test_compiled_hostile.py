"""
The hostile calls that crashed the C extensions (issue 35), each in a process of its own.

Each case is a short program that once killed its process (a segfault, a use after free,
a read through NULL); now it must end normally, the call refused with an error or the object
unchanged. A crash is the case's own failure, not the test run's. test_compiled_fuzz.py
searches for more of them; make sanitize runs both under ASan and UBSan.
"""

import os
import subprocess
import sys
import textwrap

from dq_fk_ros.kinematics.kernel import kernel_info
from dq_fk_ros.messages.cdr import COMPILED
import pytest

pytestmark = pytest.mark.skipif(
    kernel_info()['active'] != 'c' or COMPILED is None,
    reason='the Python paths are active (DQ_FK_PURE_PYTHON or no compiler): nothing compiled')

PRELUDE = """
import numpy as np
from dq_fk_ros.kinematics import _kernel
from dq_fk_ros.kinematics.chain_engines import kernel_chain_args
from dq_fk_ros.kinematics.dh import DHJoint, KinematicChain
def refused(call, *args, **kwargs):
    try:
        call(*args, **kwargs)
    except (TypeError, ValueError, IndexError, OverflowError) as exc:
        return type(exc).__name__
    return 'accepted'
def fixed_chain(n):
    return KinematicChain([DHJoint(a=.1, d=.01 * i, joint_type='fixed') for i in range(n)])
def model_of(chain, n_links=0):
    parts = (chain.engine.kernel_chain, -1, np.zeros(chain.dof),
             np.array(chain.table.pose_rows, dtype=float).reshape(-1, 10), True)
    return _kernel.Model([parts], np.zeros((n_links, 17)), chain.dof), parts
"""

READER = """
import sys
sys.path.insert(0, 'test/unit')
from dq_fk_ros.messages import _cdr
from test_joint_states import reader_arguments
good, raw = reader_arguments()
out = np.empty(3)
"""

CASES = {
    # the size check multiplied n * per and wrapped: 2**57 configurations, 16 frames
    'chain batch of 2**57 configurations': """
chain = fixed_chain(15)
print(refused(chain.forward_all_batch, np.empty((2**57, 0)), out=np.empty((0, 16, 8))))
""",
    # 7 * n_relative * N wrapped to 0 in Model.poses_batch
    'model batch whose size wraps': """
model, _ = model_of(fixed_chain(32))
print(refused(model.poses_batch, np.empty((2**59, 0)), None, np.empty((0, 7))))
print(refused(model.poses_batch, np.empty((2**59, 0)), np.empty((0, 7)), np.empty((0, 7))))
""",
    # re-initialising a Chain a Model holds freed the program the model then ran
    'a chain re-initialised under its model': """
chain = KinematicChain([DHJoint(a=.2, name=f'j{i}') for i in range(6)])
model, parts = model_of(chain)
small = kernel_chain_args(fixed_chain(1).table)
print(refused(parts[0].__init__, small[0], small[1], None, 0))
relative = np.empty((model.n_relative, 7))
model.poses(np.zeros(6), None, relative)
print(bool(np.isfinite(relative).all()))
""",
    # an argument's __bool__ re-ran Model.__init__ while the arguments were parsed
    'a model re-initialised from its own arguments': """
model, parts = model_of(fixed_chain(3))
class Evil:
    def __bool__(self):
        try:
            model.__init__([parts], np.zeros((0, 17)), 0)
        except TypeError:
            pass
        return True
    def __index__(self):
        self.__bool__()
        return 0
print(refused(model.__init__, [parts[:4] + (Evil(),)], np.zeros((0, 17)), 0))
print(refused(model.__init__, [parts], np.zeros((0, 17)), Evil()))
chains = [parts] + [parts[:1] + (Evil(),) + parts[2:]] * 2  # hung from frame 0
made = _kernel.Model(chains, np.zeros((0, 17)), 0)
relative = np.empty((model.n_relative, 7))
model.poses(np.zeros(0), None, relative)
print(made.n_frames, bool(np.isfinite(relative).all()))
""",
    # a failed re-init left the new offsets behind: read() went out of the message
    'a joint state reader after a failed re-init': READER + """
reader = _cdr.JointStateReader(**good)
print(refused(reader.__init__, **{**good, 'positions_at': 10**6}))
print(reader.read(raw, None, [0.0] * 3, [0.0] * 3, out, np.empty(3)))
""",
    # last_stamp's __index__ re-ran a failing init after the length checks: NULL read
    'a joint state reader re-initialised by the stamp': READER + """
reader = _cdr.JointStateReader(**good)
q = [0.0] * 3
class Stamp:
    def __index__(self):
        try:
            reader.__init__(**{**good, 'lower': ['x']})
        except TypeError:
            pass
        q.clear()
        return 0
print(refused(reader.read, raw, Stamp(), q, [0.0] * 3, out, np.empty(3)))
print(reader.read(raw, None, [0.0] * 3, [0.0] * 3, out, np.empty(3)))
""",
    # positions_at=2**63-8 passed the bounds check by signed overflow
    'a joint state reader with positions at 2**63-8': READER + """
print(refused(_cdr.JointStateReader, **{**good, 'positions_at': 2**63 - 8}))
print(refused(_cdr.JointStateReader, **{**good, 'velocities_at': 2**63 - 8}))
""",
    # the same list as q and qdot: each slot replaced twice, a float released twice
    'a joint state reader given one list as q and qdot': READER + """
reader = _cdr.JointStateReader(**good)
for _ in range(5):
    q = [0.0] * 3
    print(refused(reader.read, raw, None, q, q, out, np.empty(3)))
print(refused(reader.read, raw, None, [0.0] * 3, [0.0] * 3, out, out))
print(reader.read(raw, None, [0.0] * 3, [0.0] * 3, out, np.empty(3)))
""",
    # gather re-read the spans it had checked while copying into a dst overlapping them
    'gather into a dst overlapping its lengths': """
from dq_fk_ros.storage import _mcap
buf = bytearray(64)
lens = np.ndarray((2,), np.int64, buffer=buf, offset=0)
offs = np.ndarray((2,), np.int64, buffer=buf, offset=16)
offs[:] = [0, 0]
lens[:] = [16, 8]
src = np.array([16, 1 << 24], np.int64).tobytes() + bytes(1000)
print(_mcap.gather(src, offs, lens, buf))
""",
    # a model with nothing to write looped 2**57 times over an empty q, holding the GIL
    'a model with nothing to write and 2**57 configurations': """
base = np.array([1., 0, 0, 0, 0, 0, 0, 0])
chain = _kernel.Chain(np.zeros((0, 7)), base, None, 0, None, True)
model = _kernel.Model([(chain, -1, np.zeros(0), np.zeros((0, 10)), True)], np.zeros((0, 17)), 0)
print(model.n_relative, model.poses_batch(np.empty((2**57, 0)), None, np.empty((0, 7))))
""",
}

EXPECTED = {
    'chain batch of 2**57 configurations': 'ValueError',
    'model batch whose size wraps': 'ValueError\nValueError',
    'a chain re-initialised under its model': 'TypeError\nTrue',
    'a model re-initialised from its own arguments': 'TypeError\nTypeError\n12 True',
    'a joint state reader after a failed re-init': 'TypeError\n10',
    'a joint state reader re-initialised by the stamp': 'ValueError\n10',
    'a joint state reader with positions at 2**63-8': 'ValueError\nValueError',
    'a joint state reader given one list as q and qdot': 'ValueError\n' * 6 + '10',
    'gather into a dst overlapping its lengths': '24',
    'a model with nothing to write and 2**57 configurations': '0 None',
}


@pytest.mark.parametrize('case', sorted(CASES))
def test_a_hostile_call_is_refused_and_crashes_nothing(case):
    code = PRELUDE + textwrap.dedent(CASES[case])
    run = subprocess.run([sys.executable, '-P', '-c', code], capture_output=True, text=True,
                         timeout=60, env=dict(os.environ, PYTHONFAULTHANDLER='1'))
    assert run.returncode == 0, f'{case}: exit {run.returncode}\n{run.stderr[-3000:]}'
    assert run.stdout.strip() == EXPECTED[case], run.stderr[-3000:]
