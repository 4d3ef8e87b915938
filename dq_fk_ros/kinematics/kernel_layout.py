"""
The records the C kernel reads, packed by the field names it exports.

``kinematics/kernel_layout.h`` is the one definition of each record's float64 fields (a
program step ``op``, a DH row's TF transform ``row``, a tree's ``link``); the kernel reads
them by its enums and exports the same names, in order, as ``_kernel.LAYOUTS``. Python
packs by those names (:func:`pack`), never by position: a field moved in the header moves
here too. ``test_kernel_layout.py`` shows a field packed in the wrong place is caught.
"""

from collections.abc import Mapping, Sequence

import numpy as np


def pack(layouts: Mapping, layout: str, records: Sequence[Mapping]) -> np.ndarray:
    """
    Return ``records`` (``{field name: value}`` each) as one ``(n, fields)`` float64 array.

    :param layouts: the kernel's ``LAYOUTS`` (``{layout: (field name, ...)}``).
    :param layout: ``'op'``, ``'row'`` or ``'link'``.
    Every field of the layout must be given, and no other (``ValueError`` otherwise).
    """
    names = tuple(layouts[layout])
    index = {name: k for k, name in enumerate(names)}
    out = np.zeros((len(records), len(names)))
    for r, record in enumerate(records):
        if record.keys() != index.keys():
            missing = sorted(set(names) - set(record))
            extra = sorted(set(record) - set(names))
            raise ValueError(f'a kernel {layout} record needs the fields {", ".join(names)} '
                             f'(missing: {missing}, unknown: {extra})')
        for name, value in record.items():
            out[r, index[name]] = value
    return out


def pose_row_record(row: Sequence[float]) -> dict:
    """Name the fields of a ``KinematicChain._pose_rows`` tuple (its order: dh.py)."""
    ca, sa, a, theta, d, scale, ti, di, s_alpha, c_alpha = row
    return {'cos_half_alpha': ca, 'sin_half_alpha': sa, 'a': a, 'theta': theta, 'd': d,
            'scale': scale, 'theta_index': ti, 'd_index': di, 'sin_alpha': s_alpha,
            'cos_alpha': c_alpha}


def link_record(attach: int, tf_parent: int, offset: Sequence[float],
                motion: tuple | None) -> dict:
    """
    Name the fields of one link of a tree's link plan.

    :param motion: None, or ``(prismatic?, axis (3), q index, multiplier, offset value)``.
    """
    record = {'attach': attach, 'tf_parent': tf_parent}
    record.update(zip(('offset_w', 'offset_x', 'offset_y', 'offset_z', 'offset_dw',
                       'offset_dx', 'offset_dy', 'offset_dz'), offset))
    if motion is None:
        record.update(motion=-1.0, axis_x=0.0, axis_y=0.0, axis_z=0.0, q_index=0.0,
                      multiplier=0.0, value=0.0)
    else:
        prismatic, (ax, ay, az), k, multiplier, value = motion
        record.update(motion=float(prismatic), axis_x=ax, axis_y=ay, axis_z=az, q_index=k,
                      multiplier=multiplier, value=value)
    return record


def program_record(step: Sequence) -> dict:
    """Name the fields of one step of a chain's program (``dh_code.ZStep``, ``XStep``)."""
    kind, p1, p2, p3, p4, p5, mark = step
    return {'kind': kind, 'p1': p1, 'p2': p2, 'p3': p3, 'p4': p4, 'p5': p5, 'mark': mark}
