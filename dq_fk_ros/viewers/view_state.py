"""
What dq_fk_view shows, shared by its ROS callbacks and its web server: :class:`ViewState`.

The TF tree received (every frame's pose composed in the fixed frame), the robot's URDF and
the meshes it lets the server serve, the counters of ``/status``. No ROS, no web server.
"""

import json
import os
import sys
import threading
import time
from typing import Optional

from dq_fk_ros.description.meshes import check_mesh_file, mesh_allow_list
from dq_fk_ros.description.packages import PackageResolver
from dq_fk_ros.description.to_urdf import is_helper_frame
from dq_fk_ros.errors import CdrError
from dq_fk_ros.kinematics.tree import compose_tree, depths, roots
from dq_fk_ros.messages.cdr_tf import TfLatest

STALE_AFTER_S = 1.0


class ViewState:
    """What the page shows, shared by the ROS callbacks and the web server (under a lock)."""

    def __init__(self, fixed_frame='', select='', stale_after_s=STALE_AFTER_S, resolver=None,
                 mesh_dirs=(), log=None, panel=None, urdf_dir=None):
        """
        Start empty; ``fixed_frame`` and ``select`` empty: chosen from the TF tree.

        :param resolver: finds the packages of ``package://`` meshes (a
            :class:`PackageResolver`; default: the ament index and ``ROS_PACKAGE_PATH``).
        :param mesh_dirs: folders ``file://`` meshes may be in.
        :param log: called with one line per mesh that cannot be served (default: stderr).
        :param panel: a :class:`~dq_fk_ros.viewers.view_panel.JointPanel` (``--joint-panel``)
            fed each URDF, or None.
        :param urdf_dir: the folder of the robot file the user chose, where relative mesh
            paths resolve (``--urdf-dir``; see
            :func:`~dq_fk_ros.description.meshes.mesh_allow_list`), or None.
        """
        self.lock = threading.Lock()
        self.resolver = resolver or PackageResolver()
        self.mesh_dirs = tuple(mesh_dirs)
        self.panel = panel
        self.urdf_dir = urdf_dir
        self.log = log or (lambda line: print(f'dq_fk_view: {line}', file=sys.stderr,
                                              flush=True))
        self.meshes = ()          # the MeshFiles of the current URDF: all that /mesh serves
        self.edges = {}          # child -> (parent, pose, static, monotonic time received)
        self.last_stamp_ns = 0   # the newest /tf stamp received (the page reports latency)
        # /tf arrives serialized (up to kHz): only the newest message of each layout
        # (publisher) is read, when poses are sent (tens of Hz)
        self.tf_latest = TfLatest()
        self.poll_tf = None       # takes what /tf has queued into take_raw_tf
        self.urdf = None
        self.urdf_version = 0
        self.fixed_frame = fixed_frame
        self.select = select
        self.stale_after_s = stale_after_s
        self.counts = {'tf_messages': 0, 'bad_input': 0, 'frames_sent': 0, 'skipped_sends': 0,
                       'clients': 0, 'clients_total': 0, 'refused_hosts': 0,
                       'refused_origins': 0}

    def take_transforms(self, transforms, static, stamp_ns=0) -> None:
        """Record ``[(parent, child, (x, y, z, qx, qy, qz, qw)), ...]`` as received now."""
        now = time.monotonic()
        with self.lock:
            self.last_stamp_ns = max(self.last_stamp_ns, stamp_ns)
            self.counts['tf_messages'] += 1
            for parent, child, pose in transforms:
                if parent and child and parent != child:
                    self.edges[child] = (parent, pose, static, now)

    def take_raw_tf(self, raw) -> None:
        """Keep a serialized /tf message if it is its layout's newest (bad bytes: counted)."""
        with self.lock:
            try:
                self.tf_latest.take(raw)
            except CdrError:  # not a TFMessage after all: counted, never fatal
                self.counts['bad_tf'] = self.counts.get('bad_tf', 0) + 1

    def take_description(self, text) -> None:
        """Record a new robot description (URDF XML) and the meshes it allows to be served."""
        with self.lock:
            if text == self.urdf:
                return
        meshes = mesh_allow_list(text, self.resolver, self.mesh_dirs, self.urdf_dir)
        if self.panel is not None:
            self.panel.take_description(text)
        for mesh in meshes:
            if mesh.problem:
                self.log(f'{mesh.problem} (a grey box stands for it)')
        with self.lock:
            self.urdf = text
            self.meshes = meshes
            self.urdf_version += 1

    def robot_message(self) -> str:
        """Return the JSON text of the robot: its URDF and where the page gets each mesh."""
        with self.lock:
            urdf, meshes = self.urdf, self.meshes
        message = {'type': 'robot', 'urdf': urdf,
                   'meshes': {m.uri: m.url or None for m in meshes}}
        if self.panel is not None:
            message['panel'] = self.panel.spec()
        return json.dumps(message)

    def mesh_path(self, index, name) -> Optional[str]:
        """Return the file served as ``/mesh/<index>/<name>``, or None (not on the list)."""
        from urllib.parse import quote
        with self.lock:
            meshes = self.meshes
        if not (0 <= index < len(meshes)) or meshes[index].path is None or \
                meshes[index].url != f'/mesh/{index}/{quote(name)}':
            return None
        path = meshes[index].path
        try:  # as it is now: the file may have been replaced since the list was made
            if os.path.realpath(path) != path:
                return None
            check_mesh_file(path)
        except ValueError:
            return None
        return path

    def frames_message(self) -> Optional[str]:
        """Return the JSON text of every frame's pose in the fixed frame (None: no frames)."""
        if self.poll_tf is not None:
            try:
                self.poll_tf()
            except Exception:  # the subscription is gone (shutting down)
                pass
        with self.lock:
            newest = self.tf_latest.pop()
        for transforms, stamp_ns in newest:
            self.take_transforms(transforms, False, stamp_ns)
        with self.lock:
            edges = {child: (parent, pose) for child, (parent, pose, _, _) in self.edges.items()}
            ages = {child: (static, received) for child, (_, _, static, received)
                    in self.edges.items()}
            stamp_ns = self.last_stamp_ns
        if not edges:
            return None
        root = self.fixed_frame or _largest_root(edges)
        poses = compose_tree(edges, root)
        below = depths(edges, root)
        select = self.select or _deepest(below)
        now = time.monotonic()
        frames = []
        for name in sorted(poses):
            static, received = ages[name]
            stale = not static and now - received > self.stale_after_s
            frames.append([name, edges[name][0], *poses[name], stale])
        return json.dumps({'type': 'frames', 'fixed_frame': root, 'select': select,
                           'stamp_ns': stamp_ns, 'frames': frames})


def _largest_root(edges):
    """Return the root with most frames below it ('world' on a tie)."""
    candidates = roots(edges) or [next(iter(edges))]
    return max(candidates, key=lambda r: (len(depths(edges, r)), r == 'world', r))


def _deepest(below):
    """Return the frame farthest from the root, not a URDF helper (the end effector, often)."""
    names = [n for n in below if not is_helper_frame(n)] or list(below)  # never a helper
    return min(names, key=lambda n: (-below[n], n)) if names else ''


__all__ = ['STALE_AFTER_S', 'ViewState']
