"""The output table: topic names for the node (rclpy resolves them) and for a bag."""

from dq_fk_ros.messages.outputs import OUTPUTS, POSE, ROBOT_DESCRIPTION, TF, TF_STATIC, TWIST


def test_a_node_gets_the_names_as_written_and_a_bag_gets_them_resolved():
    assert POSE.topic_for('tool0') == '~/pose/tool0'
    assert POSE.topic_for('tool0', '/dq_fk_node') == '/dq_fk_node/pose/tool0'
    assert TWIST.topic_for('tool0', '/arm') == '/arm/twist/tool0'
    assert ROBOT_DESCRIPTION.topic_for() == 'robot_description'
    assert ROBOT_DESCRIPTION.topic_for('', '/dq_fk_node') == '/robot_description'
    assert TF.topic_for('', '/dq_fk_node') == '/tf' == TF.topic


def test_the_rows_are_rsps_where_rsp_has_them():
    """robot_state_publisher's QoS: /tf depth 100, /tf_static and the URDF latched, depth 1."""
    assert (TF.depth, TF.latched) == (100, False)
    assert (TF_STATIC.depth, TF_STATIC.latched) == (1, True)
    assert (ROBOT_DESCRIPTION.depth, ROBOT_DESCRIPTION.latched) == (1, True)
    assert len({o.topic for o in OUTPUTS}) == len(OUTPUTS)
    assert all(o.msgtype.count('/msg/') == 1 for o in OUTPUTS)


def test_each_frame_rule_is_an_attribute_of_the_output_plan():
    from dq_fk_ros.description.shipped import shipped_robot_path
    from dq_fk_ros.description.schema import load_robot_description
    from dq_fk_ros.messages.output_plan import OutputPlan
    plan = OutputPlan(load_robot_description(shipped_robot_path('rl15')), '', None)
    for output in OUTPUTS:
        if output.plan:
            assert len(getattr(plan, output.plan)) > 0, output
    assert len(plan.moving_edges) == 6  # the RL15's six joints, one moving transform each
