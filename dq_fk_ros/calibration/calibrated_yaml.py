"""
The robot file with its identified DH rows: everything else (base, tool, links, comments) kept.

:func:`calibrated_yaml` rewrites the ``theta, d, a, alpha`` of each entry of a DH file's
``chain`` in the file's own units (``units: {length, angle}``), round trip with
ruamel.yaml so that comments, order and flow style stay; a comment at the top says where
the values came from. The entries are matched to the chain's rows one to one, and each
entry's nominal values are checked against the model's first (a file that does not
describe the model is refused, one line).
"""

import io
import math

from dq_fk_ros.calibration.dh_model import ROW_FIELDS
from dq_fk_ros.description.schema import ANGLE_UNITS, LENGTH_UNITS
from dq_fk_ros.errors import RobotDescriptionError
import numpy as np


def calibrated_yaml(text: str, source: str, nominal_rows: np.ndarray, rows: np.ndarray,
                    note: str) -> str:
    """
    Return ``text`` (a DH robot file) with its chain's rows set to ``rows``.

    :param nominal_rows: ``(n, 4)`` the model's rows as loaded from ``text`` (theta, d, a,
        alpha; m, rad): each entry must hold them.
    :param rows: ``(n, 4)`` the identified rows, same order and units.
    :param note: the comment put at the top (one line per line of it).
    """
    from ruamel.yaml import YAML
    yaml = YAML()
    yaml.preserve_quotes = True
    yaml.width = 100
    doc = yaml.load(text)
    units = doc.get('units') or {}
    length = LENGTH_UNITS.get(str(units.get('length', 'm')), 1.0)
    angle = ANGLE_UNITS.get(str(units.get('angle', 'rad')), 1.0)
    chain = doc.get('chain')
    if not isinstance(chain, list) or len(chain) != len(rows):
        raise RobotDescriptionError(f'{source}: its chain has {len(chain or [])} rows, the '
                                    f'model {len(rows)}; cannot write the calibrated rows')
    scale = {'theta': angle, 'd': length, 'a': length, 'alpha': angle}
    for i, entry in enumerate(chain):
        for j, field in enumerate(ROW_FIELDS):
            written = float(entry.get(field, 0.0)) * scale[field]
            if not math.isclose(written, nominal_rows[i, j], rel_tol=1e-9, abs_tol=1e-12):
                raise RobotDescriptionError(f'{source}: chain row {i + 1} field {field} is not '
                                            f"the model's; cannot write the calibrated rows")
            entry[field] = float(f'{rows[i, j] / scale[field]:.10g}')
    doc.yaml_set_start_comment(note)
    out = io.StringIO()
    yaml.dump(doc, out)
    return out.getvalue()


__all__ = ['calibrated_yaml']
