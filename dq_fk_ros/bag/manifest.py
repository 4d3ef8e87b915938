"""
What a fleet run has finished, kept in the output folder so the next run can skip it.

``OUT/.dq_fk_fleet/manifest.json`` records, per bag, the input's files (names, sizes,
modification times), a hash of its summary (an MCAP file's summary section, a sqlite3 or
ROS 1 file's first and last 64 KiB), the run's robot and options, and the output's message
count per topic. A bag is complete when all of these still match and its output says so. An
output is written in ``OUT/.dq_fk_fleet/work``, renamed into place, and only then recorded:
a run killed at any point leaves nothing that would be taken as complete. One run at a time
may write an output folder (a lock).

The state folder's name is reserved: no bag may be named so (:func:`check_bag_name`). A
manifest that is not what the fleet wrote (hand-edited, truncated, another version, too
large) is set aside as ``manifest.json.set-aside-<time>``, said in one line
(:attr:`FleetState.notes`), and every bag it named is processed again.
"""

from dataclasses import asdict
import fcntl
import hashlib
import json
import os
import shutil
import stat
import struct
import time

from dq_fk_ros.bag.join import topic_counts
from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.reader_interface import check_bag_files

STATE = '.dq_fk_fleet'
VERSION = 1
EDGE_BYTES = 64 * 1024
MAX_SUMMARY_BYTES = 64 * 1024 * 1024
FOOTER_BYTES = 37  # MCAP: footer record (1 + 8 + 20) and the closing magic (8)
MAX_MANIFEST_BYTES = 1 << 30  # a million bags' entries fit many times over


def check_bag_name(name: str) -> None:
    """Refuse a bag whose output would be the fleet's state folder (or lie inside it)."""
    if name.split(os.sep, 1)[0] == STATE or name.split('/', 1)[0] == STATE:
        raise BagError(f"{name}: {STATE} is the name of the fleet's own state folder in "
                       f'--output-dir; rename the bag')


def _is_fingerprint(value):
    return (isinstance(value, dict) and set(value) == {'files', 'summary_sha256'}
            and isinstance(value['summary_sha256'], str)
            and isinstance(value['files'], list)
            and all(isinstance(f, list) and len(f) == 3 and isinstance(f[0], str)
                    and all(type(v) is int for v in f[1:]) for f in value['files']))


def _is_entry(entry):
    return (isinstance(entry, dict) and set(entry) == {'input', 'options', 'output'}
            and isinstance(entry['options'], str) and _is_fingerprint(entry['input'])
            and isinstance(entry['output'], dict)
            and all(isinstance(k, str) and type(v) is int for k, v in entry['output'].items()))


def manifest_bags(text: bytes) -> dict | None:
    """Return the bags of a manifest as the fleet writes it; None for anything else."""
    try:
        data = json.loads(text)
    except (ValueError, RecursionError):  # not JSON, or nested past Python's stack
        return None
    if not (isinstance(data, dict) and set(data) == {'version', 'bags'}
            and data['version'] == VERSION and type(data['version']) is int
            and isinstance(data['bags'], dict)):
        return None
    if not all(isinstance(k, str) and _is_entry(v) for k, v in data['bags'].items()):
        return None
    return data['bags']


def input_fingerprint(path) -> dict:
    """Return the files (name, size, mtime in ns) of a bag and a hash of their summaries."""
    path = os.fspath(path)
    check_bag_files(path)   # (a FIFO would block the read below for ever)
    if os.path.isdir(path):
        names = sorted(n for n in os.listdir(path) if os.path.isfile(os.path.join(path, n)))
        files = [os.path.join(path, n) for n in names]
    else:
        files = [path]
    digest = hashlib.sha256()
    entries = []
    for name in files:
        st = os.stat(name)
        entries.append([os.path.basename(name), st.st_size, st.st_mtime_ns])
        digest.update(_summary_bytes(name, st.st_size))
    return {'files': entries, 'summary_sha256': digest.hexdigest()}


def _summary_bytes(name, size):
    """Return an MCAP file's summary section, or another file's first and last 64 KiB."""
    with open(name, 'rb') as stream:
        if name.endswith('.mcap') and size > FOOTER_BYTES:
            stream.seek(size - FOOTER_BYTES)
            footer = stream.read(FOOTER_BYTES)
            start = struct.unpack_from('<Q', footer, 9)[0]
            if 0 < start < size and size - start <= MAX_SUMMARY_BYTES:
                stream.seek(start)
                return stream.read(size - start)
        head = stream.read(EDGE_BYTES)
        stream.seek(max(size - EDGE_BYTES, 0))
        return head + stream.read(EDGE_BYTES)


def options_fingerprint(spec, options) -> str:
    """Return a hash of the robot (its file's bytes too) and the options of a run."""
    from dq_fk_ros.description.loading import resolve_robot
    digest = hashlib.sha256(json.dumps(
        [asdict(spec), {k: v for k, v in asdict(options).items() if k != 'progress'}],
        sort_keys=True, default=str).encode())
    try:
        with open(resolve_robot(spec.robot), 'rb') as stream:
            digest.update(stream.read())
    except (OSError, ValueError):
        pass
    return digest.hexdigest()


def _open_lock(path) -> int:
    """
    Open (or make) the lock file ``path``; return its descriptor.

    Never through a symbolic link, never truncating, never a FIFO or device (``O_NOFOLLOW``,
    no ``O_TRUNC``, ``O_NONBLOCK``, then ``fstat``): a link planted as the lock would have
    made the run empty the file it names. Raises :class:`~dq_fk_ros.errors.BagError`.
    """
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK
                     | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise BagError(f'{path}: cannot be the lock ({exc.strerror}: a symbolic link or '
                       f'not a file?); remove it') from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise BagError(f'{path}: not a regular file; remove it')
    return fd


class FleetState:
    """The state folder of an output folder: lock, manifest, work folders (a context)."""

    def __init__(self, output_dir, spec, options):
        """Note the output folder and the run's robot and options."""
        self.output_dir = os.fspath(output_dir)
        self.folder = os.path.join(self.output_dir, STATE)
        self.work = os.path.join(self.folder, 'work')
        self.options = options_fingerprint(spec, options)
        self.bags = {}
        self.notes = []  # one line each: what the run should tell its user
        self._lock = None

    def __enter__(self):
        """Take the lock, read the manifest, clear a killed run's work folders."""
        if os.path.islink(self.folder) or (os.path.lexists(self.folder)
                                           and not os.path.isdir(self.folder)):
            raise BagError(f'{self.folder}: not a folder of this fleet (a link or a file); '
                           f'remove it or choose another --output-dir')
        os.makedirs(self.folder, exist_ok=True)
        self._lock = _open_lock(os.path.join(self.folder, 'lock'))
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(self._lock)
            raise BagError(f'{self.output_dir}: another dq_fk_bag run is writing this output '
                           f'folder') from None
        shutil.rmtree(self.work, ignore_errors=True)
        os.makedirs(self.work)
        self.bags = self._read_manifest()
        return self

    def _read_manifest(self):
        """Return the manifest's bags; one not written by the fleet is set aside (a note)."""
        path = os.path.join(self.folder, 'manifest.json')
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
        except FileNotFoundError:
            return {}
        except OSError:  # a link, a folder, unreadable
            bags = None
        else:
            with os.fdopen(fd, 'rb') as stream:
                size = os.fstat(stream.fileno()).st_size
                bags = (manifest_bags(stream.read()) if size <= MAX_MANIFEST_BYTES
                        and stat.S_ISREG(os.fstat(stream.fileno()).st_mode) else None)
        if bags is None:
            aside = f'{path}.set-aside-{time.strftime("%Y%m%dT%H%M%S")}-{os.getpid()}'
            os.rename(path, aside)
            self.notes.append(f'{path}: not a manifest this fleet wrote; set aside as '
                              f'{os.path.basename(aside)}, every bag is processed again')
            return {}
        return bags

    def __exit__(self, *exc):
        """Remove the work folders and release the lock."""
        shutil.rmtree(self.work, ignore_errors=True)
        os.close(self._lock)

    def complete(self, name, input_path, output) -> bool:
        """Say whether ``name``'s output is complete for this input, robot and options."""
        entry = self.bags.get(name)
        if not entry or entry.get('options') != self.options:
            return False
        try:
            return (entry.get('input') == input_fingerprint(input_path)
                    and os.path.isdir(output) and not os.path.islink(output)
                    and topic_counts(output) == entry.get('output'))
        except Exception:  # damaged (OSError, BagError, a malformed entry...): redone
            return False

    def work_folder(self, name) -> str:
        """Return a new empty work folder for bag ``name``."""
        folder = os.path.join(self.work, hashlib.sha256(name.encode()).hexdigest()[:16])
        os.makedirs(folder)
        return folder

    def place(self, name, input_path, built, final) -> dict:
        """
        Move the finished output ``built`` to ``final`` (replacing it); record it.

        Returns the output's message count per topic (what the manifest records).
        """
        out = os.path.realpath(self.output_dir)
        parent = os.path.dirname(os.path.abspath(final))
        os.makedirs(parent, exist_ok=True)
        real = os.path.realpath(parent)
        if not (real == out or real.startswith(out + os.sep)) or os.path.islink(final):
            raise BagError(f'{final}: a symbolic link on the way; not writing through it')
        self.forget(name)
        if os.path.lexists(final):
            shutil.rmtree(final) if os.path.isdir(final) else os.remove(final)
        os.rename(built, final)
        counts = topic_counts(final)
        self.bags[name] = {'input': input_fingerprint(input_path), 'options': self.options,
                           'output': counts}
        self._save()
        return counts

    def forget(self, name) -> None:
        """Drop ``name`` from the manifest (its output is no longer known complete)."""
        if self.bags.pop(name, None) is not None:
            self._save()

    def _save(self):
        path = os.path.join(self.folder, 'manifest.json')
        if os.path.lexists(path + '.new'):
            os.remove(path + '.new')  # (a link left there is not written through)
        fd = os.open(path + '.new', os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
        with os.fdopen(fd, 'w', encoding='utf-8') as stream:
            json.dump({'version': VERSION, 'bags': self.bags}, stream, indent=1,
                      sort_keys=True)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(path + '.new', path)


__all__ = ['check_bag_name', 'FleetState', 'input_fingerprint', 'manifest_bags',
           'options_fingerprint']
