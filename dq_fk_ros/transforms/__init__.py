"""
TF read back without tf2 and without ROS: tf2's BufferCore over arrays, in integer ns.

:class:`~dq_fk_ros.transforms.buffer_core.BufferCore` and the exceptions; the ROS-typed
``Buffer`` and ``TransformListener`` are in :mod:`dq_fk_ros.tf` (tf2_ros's names).
"""
