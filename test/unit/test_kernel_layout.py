"""
The records Python packs for the C kernel: one layout (kernel_layout.h), read by name.

The kernel exports its field names (``_kernel.LAYOUTS``); :mod:`dq_fk_ros.kinematics.
kernel_layout` packs by them. These tests hold the two sides to the contract: every record
Python builds names each field once, and a field packed in another's place changes what the
kernel computes (so the equality tests of test_kernel.py would see it).
"""

import os
import sys

from dq_fk_ros.description.schema import parse_robot_description
from dq_fk_ros.kinematics.kernel import KERNEL
from dq_fk_ros.kinematics.kernel_layout import (
    link_record, pack, pose_row_record, program_record)
import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_links import ARM  # noqa: E402, I100 (a chain with fixed, mimic and own-joint links)

needs_kernel = pytest.mark.skipif(KERNEL is None, reason='the C kernel is not built here')
# what the C side must offer Python: the names this package packs, per record
OP = ('kind', 'p1', 'p2', 'p3', 'p4', 'p5', 'mark')


@needs_kernel
def test_the_kernel_exports_each_layout_once_with_unique_names():
    layouts = KERNEL.LAYOUTS
    assert sorted(layouts) == ['link', 'op', 'row']
    for names in layouts.values():
        assert len(set(names)) == len(names) and all(isinstance(n, str) for n in names)
    assert layouts['op'] == OP  # dh_code.ZStep / XStep: kind first, mark last, 7 fields
    assert len(layouts['row']) == 10 and len(layouts['link']) == 17


@needs_kernel
def test_every_record_python_builds_names_each_field_of_its_layout():
    model = parse_robot_description(ARM)
    kin = model.kinematics
    for op in model.chain.table.program:
        assert program_record(op).keys() == set(KERNEL.LAYOUTS['op'])
    for row in model.chain.table.pose_rows:
        assert pose_row_record(row).keys() == set(KERNEL.LAYOUTS['row'])
    for link in kin.links:
        assert link_record(*link).keys() == set(KERNEL.LAYOUTS['link'])


def test_a_record_that_misses_or_adds_a_field_is_refused():
    layouts = {'link': ('attach', 'value')}
    assert pack(layouts, 'link', [{'value': 2.0, 'attach': 1.0}]).tolist() == [[1.0, 2.0]]
    with pytest.raises(ValueError, match=r"missing: \['value'\], unknown: \['extra'\]"):
        pack(layouts, 'link', [{'attach': 1.0, 'extra': 0.0}])


@needs_kernel
@pytest.mark.parametrize('swap', [('multiplier', 'value'), ('attach', 'tf_parent'),
                                  ('axis_x', 'axis_y'), ('motion', 'q_index')])
def test_a_link_field_packed_in_the_wrong_place_changes_the_poses(swap):
    model = parse_robot_description(ARM)
    kin = model.kinematics
    q = np.linspace(0.2, 0.7, model.dof)
    reference = np.array(kin.frame_poses_general(q)[0])
    absolute, _ = kin.frame_pose_arrays(q)
    np.testing.assert_allclose(absolute, reference, atol=1e-12)  # the contract kept
    a, b = swap
    names = list(KERNEL.LAYOUTS['link'])
    i, j = names.index(a), names.index(b)
    names[i], names[j] = b, a
    wrong = {**KERNEL.LAYOUTS, 'link': tuple(names)}
    links = pack(wrong, 'link', [link_record(*link) for link in kin.links])
    chains = [(model.chain.engine.kernel_chain, -1, np.arange(model.chain.dof, dtype=float),
               pack(KERNEL.LAYOUTS, 'row',
                    [pose_row_record(r) for r in model.chain.table.pose_rows]), True)]
    try:
        broken = KERNEL.Model(chains, links, model.dof)
    except ValueError:
        return  # refused: an index out of range (also a contract the kernel checks)
    out = np.empty_like(absolute)
    broken.poses(q, out, np.empty((kin.n_transforms, 7)))
    assert not np.allclose(out, reference, atol=1e-9)
