"""
What a calibration found, for people and programs: REPORT.json's content and the residual plot.

:func:`report` is a JSON-ready dict: the two frames fitted (``fixed_frame_in_measurement``,
``measured_in_end``, each ``{xyz (m), quaternion_xyzw}``), every parameter's nominal and
calibrated value, change and standard deviation (m or rad), ``unidentifiable`` (the names
held at their nominal values), the noise used, the observability index, and the residuals
before (the two frames alone fitted to the published table) and after, on the fit and on
the held-out part. :func:`plot_residuals` draws the position errors before and after.
"""

from dq_fk_ros.calibration.dh_model import quaternion_of_rotvec
from dq_fk_ros.calibration.identify import Calibration
import numpy as np


def frame_entry(values) -> dict:
    """Return ``{xyz, quaternion_xyzw}`` of a translation and rotation vector (6 values)."""
    w, x, y, z = quaternion_of_rotvec(np.asarray(values[3:], dtype=float))
    return {'xyz': [float(v) for v in values[:3]], 'quaternion_xyzw': [x, y, z, w]}


def report(result: Calibration, sources: dict) -> dict:
    """Return REPORT.json's content (module doc); ``sources``: what was read, to say so."""
    model = result.model
    names, angular = model.names, model.angular
    n = 4 * len(model.row_names)
    held = set(result.held)
    parameters = []
    for k, name in enumerate(names):
        parameters.append({
            'name': name, 'unit': 'rad' if angular[k] else 'm',
            'nominal': float(result.nominal[k]), 'calibrated': float(result.params[k]),
            'change': float(result.params[k] - result.nominal[k]),
            'std': float(result.std[k]), 'identified': k not in held})
    residuals = {}
    for when in ('before', 'after'):
        residuals[when] = {part: result.residuals[f'{when}_{part}']
                           for part in ('fit', 'holdout') if f'{when}_{part}' in result.residuals}
    return {
        **sources,
        'convention': model.convention,
        'fixed_frame_in_measurement': frame_entry(result.params[n:n + 6]),
        'measured_in_end': frame_entry(result.params[n + 6:n + 12]),
        'parameters': parameters,
        'unidentifiable': [names[k] for k in result.held],
        'noise': {'position_m': result.sigma_position,
                  'orientation_rad': result.sigma_orientation},
        'observability_index_m': result.observability,
        'residuals': residuals,
    }


def plot_residuals(path, before: np.ndarray, after: np.ndarray, title: str) -> None:
    """Write a PNG of the position error per measurement, before and after (mm)."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot
    figure, axes = pyplot.subplots(figsize=(8, 4), dpi=100)
    index = np.arange(len(before))
    axes.bar(index - 0.2, 1e3 * np.asarray(before), width=0.4, label='before (frames fitted)')
    axes.bar(index + 0.2, 1e3 * np.asarray(after), width=0.4, label='after (DH identified)')
    axes.set_xlabel('measurement')
    axes.set_ylabel('position error (mm)')
    axes.set_title(title)
    axes.legend()
    figure.tight_layout()
    figure.savefig(path, format='png')
    pyplot.close(figure)


__all__ = ['frame_entry', 'plot_residuals', 'report']
