"""Reports of vibration modes: their plain data (``--json``), their text table and the modes of a
config file's joint or spine at its unloaded equilibrium: what ``tensegrity-stiffness modes``
prints and draws.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.chain_dynamics import ChainDynamics
from tensegrity_stiffness.mechanics.inertia import LinkInertia
from tensegrity_stiffness.mechanics.joint_dynamics import JointDynamics
from tensegrity_stiffness.mechanics.modes import JointModes

FloatArray = NDArray[np.float64]


def modes_report(modes: JointModes, inertias: Sequence[LinkInertia] | None = None,
                 string_damping: Any = None) -> dict[str, Any]:
    """Plain data of :class:`JointModes` (for ``--json`` and tables): frequencies (Hz), damping
    ratios, the shapes (real parts, screw coordinates) and twists, ``stable``, the state and the
    inertia parameters it was computed with."""
    out: dict[str, Any] = {
        'stable': modes.stable,
        'screw': np.asarray(modes.screw).tolist(),
        'modes': [{'index': k + 1, 'frequency_hz': float(modes.frequencies[k]),
                   'damping_ratio': float(modes.damping_ratios[k]),
                   'eigenvalue': [float(modes.eigenvalues[k].real),
                                  float(modes.eigenvalues[k].imag)],
                   'shape': modes.shapes[k].real.tolist(),
                   'twist': modes.twists[k].tolist()}
                  for k in range(len(modes.frequencies))],
    }
    if inertias is not None:
        out['inertias'] = [{'mass': li.mass, 'com': li.com.tolist(),
                            'inertia': None if li.inertia is None else li.inertia.tolist()}
                           for li in inertias]
    if string_damping is not None:
        out['string_damping'] = np.asarray(string_damping, dtype=float).tolist()
    return out


def format_modes(modes: JointModes) -> str:
    """A text table of the modes (frequency, damping ratio, dominant twist component)."""
    names = ('dv_x', 'dv_y', 'dv_z', 'dw_x', 'dw_y', 'dw_z')
    # Rounded first, + 0.0: a ratio of rounding noise (-1e-17) prints 0.0000, not -0.0000.
    ratios = np.round(modes.damping_ratios, 4) + 0.0
    lines = ['mode  frequency (Hz)  damping ratio  dominant twist component',
             *(f'{k + 1:4d}  {modes.frequencies[k]:14.4f}  {ratios[k]:13.4f}  '
               f'{_dominant(modes.twists[k], names)}' for k in range(len(modes.frequencies))),
             f'stable: {"yes" if modes.stable else "NO"}']
    return '\n'.join(lines)


def _dominant(twist: FloatArray, names: Sequence[str]) -> str:
    k = int(np.argmax(np.abs(twist)))
    prefix = '' if twist.size == 6 else f'joint {k // 6 + 1} '
    return prefix + names[k % 6]


def modes_from_config(config_path: Any = None, spine: bool = False,
                      string_damping: ArrayLike | None = None
                      ) -> tuple[JointDynamics | ChainDynamics, JointModes, dict[str, Any]]:
    """The dynamics of a config file's joint (``spine``: spine), its modes at the unloaded
    equilibrium and their :func:`modes_report`: what ``tensegrity-stiffness modes`` prints and
    draws. Default config: the packaged one; ``string_damping`` (N s/m) default: the config's
    ``dynamics.string_damping`` or 0. ValueError names a bad field."""
    from pathlib import Path

    from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG
    from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium

    name = DEFAULT_SPINE_CONFIG if spine else config.DEFAULT_JOINT_CONFIG
    path = Path(config_path) if config_path else config.packaged_config_path(name)
    document = config.load_yaml(path)
    if spine:
        from tensegrity_stiffness.mechanics.chain import solve_chain_equilibrium

        cd = ChainDynamics.from_config(document, string_damping)
        # The spine's rest pose carries its links' weights (chain.link_masses, chain.gravity):
        # the equilibrium under no tip load, started from each joint's unloaded screw.
        res = solve_chain_equilibrium(cd.chain, np.zeros(6),
                                      initial_screws=cd.chain.unloaded_screws())
        if not res.success:
            raise ValueError(f'config {path}: no equilibrium of the spine under its links\' '
                             f'weights ({res.message})')
        modes = cd.modes(res.screws)
        return cd, modes, modes_report(modes, cd.inertias, None)
    jd = JointDynamics.from_config(document, string_damping)
    res = solve_equilibrium(jd.model, np.zeros(6))
    if not res.success:
        raise ValueError(f'config {path}: no unloaded equilibrium ({res.message})')
    modes = jd.modes(res.screw)
    return jd, modes, modes_report(modes, [jd.inertia], jd.string_damping)
