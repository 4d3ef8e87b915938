"""The test run's DDS domain: one in which no participant it did not start is seen."""

import socket

import dds_domains
from dds_domains import acquire_private_domain_id, bound_udp_ports, domain_in_use


def test_a_domain_with_a_foreign_participant_is_seen_as_in_use():
    for domain_id in range(60, 102):  # one whose ports are free now
        if not domain_in_use(domain_id):
            break
    port = 7400 + 250 * domain_id + 10  # a participant's unicast discovery port
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind(('127.0.0.1', port))
    except OSError:
        sock.close()
        return  # (taken meanwhile: then it is in use anyway)
    try:
        assert port in bound_udp_ports()
        assert domain_in_use(domain_id)
        assert not domain_in_use(domain_id, ports={port + 250})  # the next domain's port
    finally:
        sock.close()
    assert not domain_in_use(domain_id, ports=set())


def test_the_run_is_given_a_domain_nobody_else_is_on(monkeypatch, ros_domain_id):
    for target in range(101, 0, -1):  # one this run (and any other) does not hold
        if target == ros_domain_id:
            continue
        monkeypatch.setattr(dds_domains, 'domain_in_use', lambda d, ports=None: d != target)
        try:
            domain_id, lock = acquire_private_domain_id()
        except RuntimeError:  # another run holds its lock: try another
            continue
        lock.close()
        assert domain_id == target
        return
    raise AssertionError('no domain id could be locked for the test')
