"""``tensegrity-stiffness calibrate RECORDING --structure FILE``: a structure's recording in
(:mod:`tensegrity_stiffness.recordings.structure_recording`), each string's stiffness and
rest-length offset fitted
(:func:`~tensegrity_stiffness.estimation.structure_calibration.calibrate_structure`), a table
with the identifiability report and a calibrated structure file out.

The calibrated file is the input document (a structure file or a ROS parameter file holding a
``structure`` section) with each string's ``stiffness`` and ``rest_length`` (nominal + fitted
offset) replaced; the offsets are in its header comment. Encoders and commanded rest lengths
stay what the motors read: the nodes that take them add the offsets given as
``joint.rest_length_offsets``.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.calibration_report import load_recording
from tensegrity_stiffness.estimation.calibration_samples import CalibrationNoise
from tensegrity_stiffness.estimation.structure_calibration import (
    StructureCalibration,
    calibrate_structure,
)
from tensegrity_stiffness.nodes.structure_node import structure_path
from tensegrity_stiffness.recordings import structure_recording
from tensegrity_stiffness.structures.structure import Structure


def calibrated_document(document: Any, result: StructureCalibration) -> Any:
    """A copy of ``document`` with each string's stiffness and rest length (+ offset)."""
    out = copy.deepcopy(document)
    section = config.parameters(out).get('structure')
    if not isinstance(section, dict) or not isinstance(section.get('strings'), list):
        raise ValueError('config has no "structure" section with strings')
    for entry, k, d in zip(section['strings'], result.stiffness, result.offsets, strict=True):
        entry['stiffness'] = float(k)
        entry['rest_length'] = float(entry['rest_length']) + float(d)
    return out


def table_lines(structure: Structure, result: StructureCalibration) -> list[str]:
    """The table (parameter, nominal, fitted, std, identifiable; N/m and mm)."""
    lines = [f"{'parameter':<40}{'nominal':>11}{'fitted':>11}{'std':>11}  identifiable"]
    for j, name in enumerate(structure.string_names):
        for label, nominal, fitted, std, scale, unit in (
                ('stiffness', structure.k[j], result.stiffness[j], result.stiffness_std[j], 1.0,
                 'N/m'),
                ('rest_length_offset', 0.0, result.offsets[j], result.offset_std[j], 1e3,
                 'mm')):
            cells = [f'{v * scale:.6g}' if math.isfinite(v) else 'n/a'
                     for v in (nominal, fitted, std)]
            head = f'{label}[{name}] {unit}'
            lines.append(f'{head:<40}{cells[0]:>11}{cells[1]:>11}{cells[2]:>11}  '
                         f"{'yes' if math.isfinite(std) else 'no'}")
    return lines


def report_dict(structure: Structure, result: StructureCalibration, recording: Any,
                indices: list[int], written: str | None) -> dict[str, Any]:
    """Everything the command found, for ``--json`` (values by parameter name)."""
    names = structure.string_names

    def by_name(prefix: str, values: np.ndarray) -> dict[str, float | None]:
        return {f'{prefix}[{s}]': float(v) if math.isfinite(v) else None
                for s, v in zip(names, values, strict=True)}

    return {
        'recording': recording.source, 'instants': len(recording), 'samples': len(indices),
        'sample_times': [float(recording.times[i]) for i in indices],
        'strings': list(names),
        'parameters': {**by_name('stiffness', result.stiffness),
                       **by_name('rest_length_offset', result.offsets)},
        'nominal': {**by_name('stiffness', structure.k),
                    **by_name('rest_length_offset', np.zeros(len(names)))},
        'std': {**by_name('stiffness', result.stiffness_std),
                **by_name('rest_length_offset', result.offset_std)},
        'identifiable': list(result.identifiable), 'unidentifiable': list(result.unidentifiable),
        'rest_length_offsets': [float(v) for v in result.offsets],
        'chi2': result.chi2, 'dof': result.dof, 'config': written,
    }


def run(recording_path: str, structure_name: str, *, fmt: str | None,
        topics: Mapping[str, str | None], noise: Mapping[str, float],
        rule: Mapping[str, float], max_age: float, out: str | None,
        progress: Callable[[int, int], None] | None = None, allow_damaged: bool = False
        ) -> tuple[StructureCalibration, dict[str, Any], list[str]]:
    """The whole command for a structure: read, pick the still instants, fit, write. Returns
    (result, report, text lines). ``topics`` override :data:`structure_recording.DEFAULT_TOPICS`
    (a topic given must be in the bag, as are the defaults of the three readings)."""
    try:
        path = structure_path(structure_name)
    except ValueError as exc:  # the node's words name its parameter
        raise ValueError(str(exc).replace('structure.config', '--structure', 1)) from None
    document = config.load_yaml(path)
    try:
        structure = Structure.from_dict(document)
    except ValueError as exc:
        raise ValueError(f'structure {path}: {exc}') from None
    wanted = dict(structure_recording.DEFAULT_TOPICS, **topics)
    recording = load_recording(recording_path, structure.n_strings, fmt, wanted,
                               structure_recording.REQUIRED, max_age, progress, allow_damaged)
    indices, samples = structure_recording.samples(recording, **rule)
    result = calibrate_structure(structure, samples, CalibrationNoise.of(noise))
    written = None
    header = [f'Calibrated by tensegrity-stiffness calibrate --structure from '
              f'{recording.source}',
              f'{len(indices)} samples; chi2/dof {result.chi2 / max(result.dof, 1):.3f}',
              *table_lines(structure, result),
              'joint.rest_length_offsets (m; for the nodes that take encoders or commands): '
              + str([round(float(v), 9) for v in result.offsets])]
    if result.unidentifiable:
        header.append('Not identifiable (held at nominal):')
        header.extend(f'  {text}' for text in result.unidentifiable)
    if out:
        written = str(config.write_yaml(out, calibrated_document(document, result), header))
    lines = [f'read {recording.source}: {len(recording)} instants, {len(indices)} still '
             'samples',
             f'fit {structure.n_strings} strings of {path}: chi2/dof '
             f'{result.chi2 / max(result.dof, 1):.3f}',
             *table_lines(structure, result)]
    if result.unidentifiable:
        lines.append('not identifiable from this recording (held at nominal):')
        lines.extend(f'  {text}' for text in result.unidentifiable)
    if written:
        lines.append(f'wrote {written} (structure)')
    return result, report_dict(structure, result, recording, indices, written), lines
