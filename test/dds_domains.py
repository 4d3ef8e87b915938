"""
The test run's DDS domain id: locked for this run, and one no participant is seen on.

conftest.py's session fixture takes it; test_domain_isolation.py tests it.
"""

import fcntl
import os
import tempfile

# Domain ids 1..101 keep the DDS ports below Linux's ephemeral range.
_DOMAIN_IDS = range(1, 102)

# DDS's well-known ports (the RTPS spec's, Fast DDS's and Cyclone's defaults): domain d
# uses UDP ports 7400 + 250 d + 0..249 (discovery and user traffic of its participants)
_PORT_BASE, _DOMAIN_GAIN = 7400, 250


def bound_udp_ports():
    """Return the UDP ports bound on this machine, any address (from /proc/net/udp, udp6)."""
    ports = set()
    for table in ('/proc/net/udp', '/proc/net/udp6'):
        try:
            with open(table, encoding='ascii') as stream:
                next(stream, None)
                for line in stream:
                    local = line.split()[1]
                    ports.add(int(local.rsplit(':', 1)[1], 16))
        except (OSError, ValueError, IndexError):
            continue
    return ports


def domain_in_use(domain_id, ports=None):
    """Say whether a DDS participant (anyone's) holds a port of ``domain_id`` on this machine."""
    low = _PORT_BASE + _DOMAIN_GAIN * domain_id
    ports = bound_udp_ports() if ports is None else ports
    return any(low <= port < low + _DOMAIN_GAIN for port in ports)


def acquire_private_domain_id():
    """
    Lock and return a domain id no other test run on this machine is using.

    A domain where a participant this run did not start is seen (another user's node, a
    robot's stack) is skipped, lock or not: the tests talk only to what they started.
    """
    lock_dir = os.path.join(tempfile.gettempdir(), 'dq_fk_ros-ros-domains')
    os.makedirs(lock_dir, exist_ok=True)
    start = os.getpid() % len(_DOMAIN_IDS)
    for k in range(len(_DOMAIN_IDS)):
        domain_id = _DOMAIN_IDS[(start + k) % len(_DOMAIN_IDS)]
        handle = open(os.path.join(lock_dir, f'{domain_id}.lock'), 'w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        if domain_in_use(domain_id):
            handle.close()
            continue
        return domain_id, handle
    raise RuntimeError(f'no free ROS_DOMAIN_ID in {_DOMAIN_IDS} (all locked in {lock_dir})')


__all__ = ['acquire_private_domain_id', 'bound_udp_ports', 'domain_in_use']
