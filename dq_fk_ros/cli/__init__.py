"""Command lines (``dq_fk``, ``dq_fk_bag``): the top layer, free to use every other."""
