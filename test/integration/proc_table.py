"""What /proc says of the processes a test started: which are alive, what they listen on."""

import os


def processes(test):
    """Return the pids of the processes for which ``test(pid)`` holds (gone ones left out)."""
    found = []
    for name in os.listdir('/proc'):
        if name.isdigit():
            try:
                if test(int(name)):
                    found.append(int(name))
            except (OSError, IndexError, ValueError):  # gone meanwhile
                pass
    return found


def proc_file(pid, what):
    """Return the bytes of ``/proc/<pid>/<what>``."""
    with open(f'/proc/{pid}/{what}', 'rb') as stream:
        return stream.read()


def proc_stat(pid):
    """Return the fields of ``/proc/<pid>/stat`` after the command's name: state, ppid, ..."""
    return proc_file(pid, 'stat').rsplit(b')', 1)[1].split()


def in_session(sid):
    """Return the live processes of the session ``sid`` (a test started it in a new one)."""
    return processes(lambda pid: os.getsid(pid) == sid and proc_stat(pid)[0] != b'Z')


def listening(pids):
    """
    Return ``{(address, port)}`` of every TCP socket the processes ``pids`` listen on.

    ``address`` as /proc/net/tcp and tcp6 print it: ``0100007F`` is 127.0.0.1,
    ``00000000`` any IPv4 interface.
    """
    inodes = set()
    for pid in pids:
        try:
            for fd in os.listdir(f'/proc/{pid}/fd'):
                link = os.readlink(f'/proc/{pid}/fd/{fd}')
                if link.startswith('socket:['):
                    inodes.add(link[8:-1])
        except OSError:  # gone meanwhile
            pass
    found = set()
    for table in ('/proc/net/tcp', '/proc/net/tcp6'):
        with open(table, encoding='ascii') as rows:
            for row in list(rows)[1:]:
                fields = row.split()
                if fields[3] == '0A' and fields[9] in inodes:  # LISTEN, one of theirs
                    address, port = fields[1].split(':')
                    found.add((address, int(port, 16)))
    return found
