"""Kinematics layer: dual quaternions and DH chains in numpy; imports nothing else."""
