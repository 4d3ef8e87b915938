"""
The mesh files a URDF's visuals name: where they are, and which of them may be served.

``dq_fk_view`` serves a robot's meshes to its page, ``dq_fk_foxglove`` to Foxglove's
``fetchAsset`` (:class:`MeshAssets`). A robot description may come from any
peer on the DDS domain, so the files it names are an allow-list built from the URDF each
time it changes, and nothing else: a ``package://`` URI is resolved by
:class:`~dq_fk_ros.description.packages.PackageResolver` and must stay inside its package
(symbolic links included); a ``file://`` URI or a plain path only inside a folder the user
allowed at start (``--mesh-dir``); every file must be a regular file ending in ``.stl``,
``.dae`` or ``.obj`` and at most :data:`MAX_MESH_BYTES`. Plain Python, no ROS.
"""

from collections.abc import Sequence
from dataclasses import dataclass
import os
import stat
import threading
from urllib.parse import quote, unquote
import xml.etree.ElementTree as ElementTree

from dq_fk_ros.description.packages import PackageNotFound, PackageResolver
from dq_fk_ros.description.symlinks import follow_keeping_names
from dq_fk_ros.description.urdf_reader import MAX_URDF_BYTES, parse_xml
from dq_fk_ros.errors import printable_line

MESH_EXTENSIONS = ('.stl', '.dae', '.obj')
MAX_MESH_BYTES = 64 << 20     # a vendor's visual mesh is a few MiB at most
MAX_MESHES = 4096             # distinct mesh files in one URDF


@dataclass(frozen=True)
class MeshFile:
    """
    One mesh a URDF names: ``uri`` as written, ``path`` the file (None: not served).

    ``url`` is where the page fetches it (``/mesh/<index>/<file name>``, empty when not
    served); ``problem`` says in one line why it is not served.
    """

    uri: str
    path: str = None
    url: str = ''
    problem: str = ''


def visual_mesh_uris(urdf_text: str) -> list[str]:
    """
    Return the distinct ``filename`` of every ``<visual>``'s ``<mesh>``, in URDF order.

    A text the URDF reader would refuse (larger than a URDF may be, or declaring XML
    entities) names none.
    """
    if len(urdf_text) > MAX_URDF_BYTES or '<!ENTITY' in urdf_text:
        return []
    try:
        root = parse_xml(urdf_text)
    except ElementTree.ParseError:
        return []
    uris = []
    for mesh in root.iterfind('link/visual/geometry/mesh'):
        uri = mesh.get('filename')
        if uri and uri not in uris:
            uris.append(uri)
    return uris[:MAX_MESHES]


def mesh_allow_list(urdf_text: str, resolver: PackageResolver,
                    mesh_dirs: Sequence[str] = (), urdf_dir: str | None = None) -> tuple:
    """
    Return a :class:`MeshFile` per mesh of the URDF's visuals: the files that may be served.

    :param resolver: a :class:`~dq_fk_ros.description.packages.PackageResolver`.
    :param mesh_dirs: folders ``file://`` URIs and absolute paths may name files in.
    :param urdf_dir: the folder of the URDF file the user chose, which relative paths
        (``meshes/base.stl``, as pybullet_data's URDFs name them) are resolved against and
        may not leave; None (a URDF from a peer on DDS): relative paths are refused.
    """
    allowed = [os.path.realpath(folder) for folder in mesh_dirs]
    urdf_dir = None if urdf_dir is None else os.path.realpath(urdf_dir)
    out = []
    for index, uri in enumerate(visual_mesh_uris(urdf_text)):
        shown = printable_line(uri, 200)
        try:
            path = _mesh_path(uri, resolver, allowed, urdf_dir)
        except (PackageNotFound, ValueError) as exc:
            out.append(MeshFile(uri, problem=f'mesh {shown}: {printable_line(exc, 300)}'))
            continue
        name = quote(os.path.basename(path))
        out.append(MeshFile(uri, path, f'/mesh/{index}/{name}'))
    return tuple(out)


def _mesh_path(uri, resolver, allowed, urdf_dir=None):
    """Return the real file ``uri`` names, or raise ValueError / PackageNotFound saying why."""
    if not uri.lower().endswith(MESH_EXTENSIONS):
        raise ValueError(f'not a mesh this page draws ({", ".join(MESH_EXTENSIONS)})')
    if uri.startswith('package://'):
        name = uri[len('package://'):].partition('/')[0]
        named = resolver.resolve(uri)   # inside its package as text ('..' refused)
        real = os.path.realpath(named)
        folder = resolver.find(name)
        root = os.path.realpath(folder)
        if os.path.commonpath([real, root]) != root:
            real = follow_keeping_names(folder, named)   # links that keep every name only
            if real is None:
                raise ValueError('outside its package')
        check_mesh_file(real)
        return real
    if uri.startswith('file://') or '://' not in uri:
        path = unquote(uri[len('file://'):]) if uri.startswith('file://') else uri
        roots = allowed
        where = 'the --mesh-dir folders' if roots else \
            'a folder given with --mesh-dir (none given)'
        if not os.path.isabs(path):
            if urdf_dir is None or uri.startswith('file://'):
                raise ValueError('a relative path: resolved only against the folder of a URDF '
                                 'file given on the command line, never for one from DDS')
            path, roots = os.path.join(urdf_dir, path), [urdf_dir]
            where = "the URDF's folder"
    else:
        raise ValueError('only package:// and file:// meshes are served')
    real = os.path.realpath(path)
    if not any(os.path.commonpath([real, root]) == root for root in roots):
        raise ValueError(f'outside {where}')
    check_mesh_file(real)
    return real


def check_mesh_file(path: str) -> None:
    """Raise ValueError unless ``path`` is a regular mesh file of at most MAX_MESH_BYTES."""
    try:
        info = os.stat(path)
    except OSError as exc:
        raise ValueError(f'cannot be read ({exc.strerror})') from None
    if not stat.S_ISREG(info.st_mode):
        raise ValueError('not a regular file')
    if info.st_size > MAX_MESH_BYTES:
        raise ValueError(f'larger than {MAX_MESH_BYTES >> 20} MiB')


def read_mesh_file(path: str) -> bytes:
    """
    Return the bytes of the mesh file ``path``, opened once and checked by its descriptor.

    Opened with ``O_NOFOLLOW`` (a link put in its place is refused), then checked on the
    open descriptor (``fstat``: a regular file of at most MAX_MESH_BYTES; on Linux, the
    file opened is ``path`` itself, not one reached through a folder link) and read from
    it: a name checked and then reopened could be a different file by then. ValueError
    says why not.
    """
    flags = os.O_RDONLY | getattr(os, 'O_NOFOLLOW', 0) | getattr(os, 'O_NONBLOCK', 0) \
        | getattr(os, 'O_CLOEXEC', 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise ValueError(f'cannot be opened ({exc.strerror})') from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise ValueError('not a regular file')
        if info.st_size > MAX_MESH_BYTES:
            raise ValueError(f'larger than {MAX_MESH_BYTES >> 20} MiB')
        proc = f'/proc/self/fd/{fd}'
        if os.path.exists(proc) and os.readlink(proc) != path:
            raise ValueError('reached through a link')
        chunks, size = [], 0
        while size <= MAX_MESH_BYTES:
            chunk = os.read(fd, 1 << 20)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > MAX_MESH_BYTES:
            raise ValueError(f'larger than {MAX_MESH_BYTES >> 20} MiB')
        return b''.join(chunks)
    finally:
        os.close(fd)


class MeshAssets:
    """
    The mesh files of the current URDF, fetched by the URI the URDF writes (thread-safe).

    What a Foxglove client's ``fetchAsset`` may read: :meth:`replace` builds the allow-list
    of a new URDF (:func:`mesh_allow_list`, the same rules as ``dq_fk_view``'s) and forgets
    the old one; :meth:`fetch` returns a listed file's bytes (:func:`read_mesh_file`) and
    None for any other URI (traversal, ``file://`` outside ``mesh_dirs``, unknown).
    """

    def __init__(self, resolver: PackageResolver, mesh_dirs: Sequence[str] = (),
                 urdf_dir: str | None = None):
        """Start with no URDF: nothing is fetchable (``urdf_dir``: :func:`mesh_allow_list`)."""
        self.resolver = resolver
        self.mesh_dirs = tuple(mesh_dirs)
        self.urdf_dir = urdf_dir
        self._paths = {}
        self._lock = threading.Lock()

    def replace(self, urdf_text: str) -> list[str]:
        """Make the meshes of ``urdf_text`` the only fetchable files; one line per refusal."""
        meshes = mesh_allow_list(urdf_text, self.resolver, self.mesh_dirs, self.urdf_dir)
        with self._lock:
            self._paths = {m.uri: m.path for m in meshes if m.path}
        return [m.problem for m in meshes if m.problem]

    def _path(self, uri):
        """Return the listed file of ``uri``, or None."""
        with self._lock:
            return self._paths.get(uri) if isinstance(uri, str) else None

    def size(self, uri: str) -> int:
        """Return how many bytes :meth:`fetch` of ``uri`` returns now (0: none, or unknown)."""
        path = self._path(uri)
        try:
            return min(os.stat(path).st_size, MAX_MESH_BYTES) if path else 0
        except OSError:
            return 0

    def fetch(self, uri: str) -> bytes | None:
        """Return the bytes of the listed mesh ``uri``, or None (not listed, or unreadable)."""
        path = self._path(uri)
        if path is None:
            return None
        try:
            return read_mesh_file(path)
        except ValueError:
            return None


__all__ = ['check_mesh_file', 'mesh_allow_list', 'MeshAssets', 'MeshFile', 'read_mesh_file',
           'visual_mesh_uris']
