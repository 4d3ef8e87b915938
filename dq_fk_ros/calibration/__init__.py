"""
Calibration layer: a DH table identified from measured poses (no ROS; bags through storage/).

:mod:`~dq_fk_ros.calibration.dh_model` (the measured pose as a function of the DH rows and
its analytic Jacobian), :mod:`~dq_fk_ros.calibration.identify` (what can be identified,
Levenberg-Marquardt, the observability index, a measurement plan),
:mod:`~dq_fk_ros.calibration.measurements` (a CSV file, a bag's poses paired with joint
states), :mod:`~dq_fk_ros.calibration.calibrated_yaml` and
:mod:`~dq_fk_ros.calibration.report` (what is written). ``dq_fk calibrate`` runs it.
"""
