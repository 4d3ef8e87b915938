"""Viewers layer: the robot live in a browser (dq_fk_view) and in Foxglove (dq_fk_foxglove)."""
