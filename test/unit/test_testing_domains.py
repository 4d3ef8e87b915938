"""The test process's DDS domain (dq_fk_ros.testing.domains): no participant it did not start."""

import os
import socket

import domain_coordinator
from dq_fk_ros.testing import domains
from dq_fk_ros.testing.domains import (bound_udp_ports, claim_domain, domain_in_use,
                                       isolate_environment, restore_environment)
import pytest


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


def test_the_run_is_given_a_domain_nobody_else_is_on(monkeypatch, tmp_path, dq_fk_domain):
    for target in range(101, 0, -1):  # one this run (and any other) does not hold
        if target == dq_fk_domain:
            continue
        monkeypatch.setattr(domains, 'domain_in_use', lambda d, ports=None: d != target)
        try:
            claim = claim_domain(str(tmp_path))
        except RuntimeError:  # held by a launch test's coordinator port: try another
            continue
        with claim:
            assert claim.domain_id == target
        return
    raise AssertionError('no domain id could be claimed for the test')


def test_ids_held_by_launch_tests_are_never_given_and_ours_never_theirs(tmp_path):
    # launch_testing and `ros2 test` take ids through domain_coordinator (a port each)
    with domain_coordinator.domain_id() as theirs:
        with claim_domain(str(tmp_path)) as ours:
            assert ours.domain_id != theirs
            with pytest.raises(RuntimeError, match='Failed to get a unique ROS domain ID'):
                with domain_coordinator.domain_id(lambda: ours.domain_id):
                    pass


def test_the_environment_is_set_for_loopback_and_given_back(monkeypatch):
    monkeypatch.setenv('ROS_STATIC_PEERS', '192.168.1.7')
    monkeypatch.setenv('ROS_DOMAIN_ID', '3')
    environ = dict(os.environ)
    saved = isolate_environment(environ, 42)
    assert environ['ROS_DOMAIN_ID'] == '42' and 'ROS_STATIC_PEERS' not in environ
    assert environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    restore_environment(environ, saved)
    assert environ == dict(os.environ)


def test_the_fixture_sets_the_domain_for_this_process(dq_fk_domain):
    assert os.environ['ROS_DOMAIN_ID'] == str(dq_fk_domain)
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
