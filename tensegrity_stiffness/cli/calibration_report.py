"""``tensegrity-stiffness calibrate``: a recording in, a calibrated config, a table and a residual
plot out (the command's logic; :mod:`tensegrity_stiffness.estimation.calibration` does the fit).

The calibrated config is the input config document (a ROS parameter file or a plain file, as
``JointModel.from_yaml`` and the nodes load them) with ``joint.stiffness``, ``joint.rest_lengths``
(nominal + fitted offset), ``joint.max_lengths`` (each string's maximum stretch kept) and
``joint.initial_screw`` (the calibrated joint's unloaded equilibrium) replaced and the fitted
offsets written as ``joint.rest_length_offsets``; the table is in its header comment. The
commanded rest lengths a controller sends (``~/rest_lengths``) stay commanded values: the nodes
that load the config add the offsets to them (stiffness_node, estimator_node, sim_node; the
controller subtracts them from its commands).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tensegrity_stiffness import config
from tensegrity_stiffness.cli import plots
from tensegrity_stiffness.estimation.calibration_results import CalibrationResult
from tensegrity_stiffness.estimation.calibration_samples import RESIDUAL_KINDS, RESIDUAL_UNITS
from tensegrity_stiffness.estimation.joint_calibration import SLACK_MARGIN, calibrate_joint
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.recordings.calibration_recording import (
    Recording,
    RecordingError,
    quasi_static_indices,
    read_bag,
    read_csv,
)

#: Size (pixels) of the residual plot.
PLOT_SIZE = (1000, 700)
#: Display units of each residual kind in the table and the plot (factor, label).
DISPLAY_UNITS = {'position': (1e3, 'mm'), 'rotation': (180.0 / math.pi, 'deg'),
                 'force': (1.0, 'N'), 'moment': (1e3, 'N mm'), 'tension': (1.0, 'N'),
                 'length': (1e3, 'mm')}


def load_recording(path: str | Path, n_strings: int, fmt: str | None = None,
                   topics: Mapping[str, str | None] | None = None,
                   required: Sequence[str] = (), max_age: float = 0.1,
                   progress: Callable[[int, int], None] | None = None,
                   allow_damaged: bool = False) -> Recording:
    """A bag (folder, .mcap or .db3) or CSV file as a :class:`Recording` (``fmt`` 'bag' or
    'csv'; default from the path: ``.csv`` is CSV); a damaged bag is refused unless
    ``allow_damaged``."""
    path = Path(path)
    if fmt is None:
        fmt = 'csv' if path.suffix.lower() == '.csv' else 'bag'
    if fmt == 'csv':
        return read_csv(path, n_strings)
    if fmt != 'bag':
        raise ValueError(f"--format must be bag or csv, got '{fmt}'")
    return read_bag(path, n_strings, dict(topics or {}), required=required, max_age=max_age,
                    progress=progress, allow_damaged=allow_damaged)


def pick_samples(recording: Recording, **rule: float) -> tuple[list[int], list[Any]]:
    """Indices and samples of the quasi-static instants; RecordingError when there is none."""
    indices = quasi_static_indices(recording, **rule)
    if not indices:
        raise RecordingError(f'{recording.source}: no quasi-static instants among '
                             f'{len(recording)} (rest lengths held and the pose still for the '
                             'window; see --window, --max-speed, --max-angular-speed)')
    return indices, recording.samples(indices)


def missing_topics(recording: Recording) -> str:
    """Words for the signals the recording lacks, by topic and option (for an error)."""
    return ''.join(f'no {signal} topic {topic} in the bag (name yours with '
                   f"--{signal.replace('_', '-')}-topic); "
                   for signal, topic in recording.absent.items())


def unloaded_screw(model: JointModel, start: np.ndarray) -> np.ndarray:
    """The calibrated joint's unloaded equilibrium from ``start`` (``start`` when it fails)."""
    eq = solve_equilibrium(model, np.zeros(6), initial_screw=start)
    return eq.screw if eq.success and eq.stable else start


def calibrated_document(document: Any, result: CalibrationResult) -> Any:
    """A copy of the config ``document`` with the joint section's stiffness, rest lengths,
    maximum lengths and initial screw taken from ``result.model``, and the fitted offsets as
    ``joint.rest_length_offsets`` (the nodes add them to commanded rest lengths)."""
    out = copy.deepcopy(document)
    params = config.parameters(out)
    joint = params.get('joint')
    if not isinstance(joint, dict):
        raise ValueError('config has no "joint" section')
    model = result.model
    joint['stiffness'] = [float(v) for v in model.k]
    joint['rest_lengths'] = [float(v) for v in model.rest_lengths]
    if np.isfinite(model.max_lengths).all() and len(joint.get('max_lengths') or []):
        joint['max_lengths'] = [float(v) for v in model.max_lengths]
    joint['initial_screw'] = [float(v) for v in unloaded_screw(model, model.initial_screw)]
    joint['rest_length_offsets'] = [float(v) for v in result.offsets]
    return out


def header_lines(result: CalibrationResult, recording: str) -> list[str]:
    """Comment lines for the calibrated config: source, table, what is not identifiable."""
    lines = [f'Calibrated by tensegrity-stiffness calibrate from {recording}',
             f'{len(result.screws)} samples, {len(result.outliers)} outliers left out, '
             f'{len(result.near_slack)} near slack kept; '
             f'chi2/dof {result.chi2 / max(result.dof, 1):.3f}',
             *table_lines(result)]
    if result.unidentifiable:
        lines.append('Not identifiable (held at nominal):')
        lines.extend(f'  {text}' for text in result.unidentifiable)
    return lines


def write_config(path: str | Path, document: Any, result: CalibrationResult,
                 recording: str) -> Path:
    """Write the calibrated config YAML (header comment + document)."""
    return config.write_yaml(path, calibrated_document(document, result),
                             header_lines(result, recording))


def _cell(value: float, scale: float = 1.0) -> str:
    return 'n/a' if value is None or not math.isfinite(value) else f'{value * scale:.6g}'


def table_lines(result: CalibrationResult) -> list[str]:
    """The parameter table (name, string, nominal, fitted, std, identifiable) and the residuals
    before and after, as text lines (stiffness in N/m, offsets in mm)."""
    lines = [f"{'parameter':<27}{'string':<14}{'nominal':>11}{'fitted':>11}{'std':>11}"
             f"  identifiable"]
    for row in result.table():
        scale, unit = (1.0, 'N/m') if row['name'].startswith('stiffness') else (1e3, 'mm')
        lines.append(f"{row['name'] + ' ' + unit:<27}{row['string']:<14}"
                     f"{_cell(row['nominal'], scale):>11}{_cell(row['fitted'], scale):>11}"
                     f"{_cell(row['std'], scale):>11}  {'yes' if row['identifiable'] else 'no'}")
    lines.append('residual RMS (before: nominal parameters, every sample; after: calibrated, '
                 'inliers):')
    for kind in RESIDUAL_KINDS:
        if kind in result.residual_rms_before:
            scale, unit = DISPLAY_UNITS[kind]
            lines.append(f'  {kind:<9} {result.residual_rms_before[kind] * scale:10.4g} -> '
                         f'{result.residual_rms_after.get(kind, math.nan) * scale:10.4g} {unit}')
    return lines


def plot_residuals(result: CalibrationResult, path: str | Path,
                   size: tuple[int, int] = PLOT_SIZE) -> Path:
    """PNG: for each measured kind, the norm of each sample's residual (display units) before
    (nominal) and after (calibrated) against the sample index; outliers marked."""
    out = plots.output_path(path)
    kinds = [k for k in RESIDUAL_KINDS if k in result.residual_rms_before]
    fig = plots.new_figure(*size)
    axes = fig.subplots(len(kinds), 1, sharex=True, squeeze=False)[:, 0]
    index = np.arange(len(result.screws))
    for ax, kind in zip(axes, kinds, strict=True):
        scale, unit = DISPLAY_UNITS[kind]
        for after, style in ((False, {'color': 'tab:gray', 'label': 'nominal'}),
                             (True, {'color': 'tab:blue', 'label': 'calibrated'})):
            r = result.residuals(kind, after) * scale
            norm = np.sqrt(np.nansum(r * r, axis=1))
            norm[np.all(np.isnan(r), axis=1)] = np.nan
            ax.plot(index, norm, '.', markersize=3, **style)
        if result.outliers:
            r = result.residuals(kind, True)[result.outliers] * scale
            ax.plot(result.outliers, np.sqrt(np.nansum(r * r, axis=1)), 'x', color='tab:red',
                    label='outlier')
        ax.set_ylabel(f'|{kind}| ({unit})')
        ax.set_yscale('log')
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc='upper right', fontsize='small')
    axes[0].set_title('Residual per sample: nominal vs calibrated parameters')
    axes[-1].set_xlabel('sample')
    return plots.save_figure(fig, out)


def report_dict(result: CalibrationResult, recording: Recording, indices: Sequence[int],
                outputs: Mapping[str, str | None]) -> dict[str, Any]:
    """Everything the command found, for ``--json``."""
    return {
        'recording': recording.source, 'instants': len(recording), 'samples': len(indices),
        'sample_times': [float(recording.times[i]) for i in indices],
        'success': result.success, 'message': result.message,
        'parameters': result.parameters, 'nominal': result.nominal, 'std': result.std,
        'identifiable': result.identifiable, 'unidentifiable': result.unidentifiable,
        'rest_length_offsets': [float(v) for v in result.offsets],
        'residual_rms_before': result.residual_rms_before,
        'residual_rms_after': result.residual_rms_after,
        'residual_units': RESIDUAL_UNITS, 'outliers': result.outliers,
        'near_slack': result.near_slack,
        'iterations': result.iterations, 'chi2': result.chi2, 'dof': result.dof,
        'singular_values': result.singular_values, 'seconds': result.seconds,
        **{key: value for key, value in outputs.items()},
    }


def run(recording_path: str, config_path: str | None, *, fmt: str | None,
        topics: Mapping[str, str | None], required: Sequence[str], fit: Sequence[str],
        noise: Mapping[str, float], loss: str, rule: Mapping[str, float], max_age: float,
        out: str | None, plot: str | None,
        progress: Callable[[str], Callable[[int, int], None]] | None = None,
        allow_damaged: bool = False
        ) -> tuple[CalibrationResult, dict[str, Any], list[str]]:
    """The whole command: read, pick, fit, write. Returns (result, report, text lines)."""
    path = Path(config_path) if config_path else config.packaged_config_path()
    document = config.load_yaml(path)
    try:
        model = JointModel.from_dict(config.section(document, 'joint'))
    except ValueError as exc:
        raise ValueError(f'config {path}: {exc}') from None
    reading = progress('read') if progress else None
    recording = load_recording(recording_path, model.n_strings, fmt, topics, required,
                               max_age, reading, allow_damaged)
    indices, samples = pick_samples(recording, **rule)
    fitting = progress('fit') if progress else None
    try:
        result = calibrate_joint(model, samples, fit=fit, noise=noise, loss=loss,
                                 progress=fitting)
    except ValueError as exc:
        raise RecordingError(f'{recording.source}: {missing_topics(recording)}{exc}'
                             if recording.absent else str(exc)) from None
    written: dict[str, str | None] = {'config': None, 'plot': None}
    if out:
        written['config'] = str(write_config(out, document, result, recording.source))
    if plot:
        written['plot'] = str(plot_residuals(result, plot))
    lines = [f'read {recording.source}: {len(recording)} instants, {len(indices)} quasi-static '
             'samples',
             f"fit {', '.join(fit)}: {result.message} in {result.iterations} iterations "
             f'({result.seconds:.2f} s); chi2/dof {result.chi2 / max(result.dof, 1):.3f}',
             *table_lines(result)]
    if result.outliers:
        lines.append(f'outliers ({len(result.outliers)} samples, left out): '
                     + ' '.join(map(str, result.outliers)))
    if result.near_slack:
        lines.append(f'near slack ({len(result.near_slack)} samples with a string within '
                     f'{SLACK_MARGIN:g} std of slack, kept, held taut): '
                     + ' '.join(map(str, result.near_slack)))
    if result.unidentifiable:
        lines.append('not identifiable from this recording (held at nominal):')
        lines.extend(f'  {text}' for text in result.unidentifiable)
    for key, value in written.items():
        if value:
            lines.append(f'wrote {value} ({key})')
    return result, report_dict(result, recording, indices, written), lines
