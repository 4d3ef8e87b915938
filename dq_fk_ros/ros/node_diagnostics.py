"""
What dq_fk_node reports: its counters on /diagnostics, what a joint state led to in its log.

The keys are listed in docs/node.md ("Diagnostics"); the level is WARN when joint states
were lost since the last report, a joint was never seen or an update was rejected.
"""

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from dq_fk_ros.messages.joint_states import INCOMPLETE, MAX_UNKNOWN_LISTED, REJECTED

WARN_EVERY_S = 5.0  # a warning repeated per message is logged at most this often


def joint_state_status(name, model, merger, lost, lost_now, input_errors,
                       age_s) -> DiagnosticStatus:
    """
    Return the ``DiagnosticStatus`` of the joint-state input.

    :param name: the status name (``<node>: joint states``).
    :param model: the robot (a :class:`~dq_fk_ros.description.robot_model.RobotModel`).
    :param merger: the node's :class:`~dq_fk_ros.messages.joint_states.JointStateMerger`.
    :param lost: joint states lost before the node took them, in all; ``lost_now``: since
        the last report.
    :param input_errors: exceptions the input thread caught.
    :param age_s: seconds since the last update (None: never).
    """
    counts = merger.counts
    # a tree waits for no joint: its transforms wait for theirs, so every joint counts
    never_seen = merger.never_seen_any if model.branches else merger.never_seen
    values = {'robot': model.name,
              'updates_received': counts['received'],
              'updates_published': counts['published'],
              'updates_incomplete': counts['incomplete'],
              'updates_rate_limited': counts['rate_limited'],
              'updates_rejected': counts['rejected'],
              'time_jumps': counts['time_jumps'],
              'joints_never_seen': ', '.join(never_seen),
              'unknown_joints': ', '.join(sorted(merger.unknown)),
              'unknown_names_unlisted': counts['unknown_names_unlisted'],
              'velocities_non_finite': counts['velocities_non_finite'],
              'updates_lost': lost,
              'input_errors': input_errors,
              'last_update_age_s': 'never' if age_s is None else f'{age_s:.3f}'}
    for key in sorted(counts):
        if key.startswith('rejected_'):
            values[key] = counts[key]
    if lost_now:
        level, message = DiagnosticStatus.WARN, \
            f'{lost_now} joint states lost before the node took them (overload?)'
    elif never_seen:
        level, message = DiagnosticStatus.WARN, f'{len(never_seen)} joints never seen'
    elif counts['rejected']:
        level, message = DiagnosticStatus.WARN, f"{counts['rejected']} updates rejected"
    else:
        level, message = DiagnosticStatus.OK, 'ok'
    level = level if isinstance(level, bytes) else bytes([level])
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=model.name,
                            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])


__all__ = ['joint_state_status']


def log_merge_result(log, result, robot, out_of_limits) -> bool:
    """
    Log what a merge result says; return whether the update is to be published.

    :param log: the node's logger; ``robot``: the robot's name; ``out_of_limits``: the
        node's policy (named in the warning).
    """
    if result.new_unknown:
        log.warn(f'ignoring joints that {robot} does not have: '
                 f'{", ".join(result.new_unknown)} (reported once)')
    if result.unknown_overflow:
        log.warn(f'more than {MAX_UNKNOWN_LISTED} unknown joint names; further ones are '
                 f'only counted (unknown_names_unlisted in /diagnostics)')
    if result.time_jump:
        log.info('joint state stamps jumped back in time; state reset')
    if result.status == REJECTED:
        log.warn(f'joint state rejected ({result.reason}): {result.detail}',
                 throttle_duration_sec=WARN_EVERY_S)
        return False
    if result.out_of_limits:
        log.warn(f'joints outside their limits ({out_of_limits}): '
                 f'{", ".join(result.out_of_limits)}', throttle_duration_sec=WARN_EVERY_S)
    if result.status == INCOMPLETE:
        log.warn(f'waiting for joints never seen: {", ".join(result.missing)}',
                 throttle_duration_sec=WARN_EVERY_S)
        return False
    return True
