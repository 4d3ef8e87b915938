"""
The real tf2 beside dq_fk_ros.tf, side by side: a lookup, and a point cloud moved.

Used by bench_tf.py, (f) and (g). The peers are not on PyPI; they are read from places the
user gives (nothing is fetched or copied into this repository):

- ``--real-tf2 ENV_LINE``: the ``export`` line ``../shared/tools/build_real_tf2.sh VENV
  GEOMETRY2_GIT_DIR OUT`` prints last (the real tf2_ros built against this venv's wheels);
  the real ``lookup_transform`` is timed on the same 130-frame tree in a process of its own.
- ``--geometry2 PATH`` and ``--common-interfaces PATH``: checkouts (or git dirs, ``jazzy``) of
  ros2/geometry2 and ros2/common_interfaces: their pure-Python ``tf2_sensor_msgs`` and
  ``sensor_msgs_py`` move the same 300 000-point cloud in a process of their own (their
  registrations go to whichever tf2_ros that process finds: the compat path's).
"""

import os
import shlex
import subprocess
import sys
import tempfile

CLOUD_POINTS = 300_000
# x y z rgb as float32 (16 bytes: a depth camera's XYZRGB), then an intensity the transform
# leaves alone
CLOUD = """
import numpy as np
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header
from geometry_msgs.msg import TransformStamped
n = {n}
rng = np.random.default_rng(5)
points = np.zeros(n, dtype=[('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('rgb', '<f4'),
                            ('intensity', '<f4')])
for name in ('x', 'y', 'z', 'rgb', 'intensity'):
    points[name] = rng.uniform(-5, 5, n)
fields = [PointField(name=f, offset=4 * k, datatype=PointField.FLOAT32, count=1)
          for k, f in enumerate(('x', 'y', 'z', 'rgb', 'intensity'))]
cloud = PointCloud2(header=Header(frame_id='camera'), height=1, width=n, fields=fields,
                    is_bigendian=False, point_step=20, row_step=20 * n, is_dense=True)
cloud.data = points.tobytes()
t = TransformStamped()
t.header.frame_id = 'base_link'
t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = 0.1, -0.2, 1.3
t.transform.rotation.x, t.transform.rotation.y = 0.5, -0.5
t.transform.rotation.z, t.transform.rotation.w = 0.5, -0.5
import time
from tf2_sensor_msgs import do_transform_cloud
best = 1e9
for _ in range(5):
    start = time.perf_counter()
    out = do_transform_cloud(cloud, t)
    best = min(best, time.perf_counter() - start)
print(best * 1e3)
"""

LOOKUP = """
import math, time
from geometry_msgs.msg import TransformStamped
from rclpy.time import Time
import tf2_ros
buffer = tf2_ros.Buffer()
S = 10**9
for step in range(100):
    for k in range(1, {frames}):
        a = 0.01 * step + k
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = f'f{{(k - 1) // 2}}', f'f{{k}}'
        t.header.stamp = Time(nanoseconds=S + step * 10_000_000).to_msg()
        t.transform.translation.x, t.transform.translation.y = a, 0.1
        t.transform.translation.z = 0.2
        t.transform.rotation.z, t.transform.rotation.w = math.sin(a / 2), math.cos(a / 2)
        buffer.set_transform(t, 'bench')
when = Time(nanoseconds=S + 505_000_000 + 1234)
best = 1e9
for _ in range(5):
    start = time.perf_counter()
    for _ in range(2000):
        buffer.lookup_transform('f127', 'f100', when)
    best = min(best, (time.perf_counter() - start) / 2000 * 1e6)
print(best)
"""


def _run(code: str, env: dict) -> float | None:
    done = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                          text=True, timeout=600)
    if done.returncode != 0:
        print(f'  (the peer failed: {(done.stderr.strip().splitlines() or [""])[-1][:200]})')
        return None
    return float(done.stdout.strip().splitlines()[-1])


def _extract(repository: str, paths, into: str) -> None:
    inner = os.path.join(repository, '.git')
    git_dir = inner if os.path.isdir(inner) else repository
    archive = subprocess.run(['git', '--git-dir', git_dir, 'archive', 'jazzy', *paths],
                             check=True, capture_output=True).stdout
    subprocess.run(['tar', '-x', '-C', into], input=archive, check=True)


def cloud_ms(pythonpath: list) -> float | None:
    """Return the best of 5 ``do_transform_cloud`` of the cloud, ms, with ``pythonpath``."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(pythonpath))
    return _run(CLOUD.format(n=CLOUD_POINTS), env)


def real_cloud_ms(geometry2: str, common_interfaces: str, compat: list) -> float | None:
    """Return geometry2's tf2_sensor_msgs (with common_interfaces' sensor_msgs_py), ms."""
    with tempfile.TemporaryDirectory(prefix='bench_tf_peers_') as work:
        _extract(geometry2, ['tf2_sensor_msgs/tf2_sensor_msgs'], work)
        _extract(common_interfaces, ['sensor_msgs_py/sensor_msgs_py'], work)
        return cloud_ms([os.path.join(work, 'tf2_sensor_msgs'),
                         os.path.join(work, 'sensor_msgs_py')] + compat[:1])


def lookup_us(env_line: str | None, compat: list, frames: int) -> float | None:
    """Return tf2_ros's lookup_transform, us: the real one (``env_line``) or the compat's."""
    env = dict(os.environ)
    if env_line:
        for word in shlex.split(env_line):
            if '=' in word and word != 'export':
                key, value = word.split('=', 1)
                env[key] = os.pathsep.join(p for p in (value, env.get(key, '')) if p)
    else:
        env['PYTHONPATH'] = os.pathsep.join(compat)
    return _run(LOOKUP.format(frames=frames), env)
