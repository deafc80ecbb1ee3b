"""docs/figures/six_bar_roll.png: the MuJoCo twin of config/examples/six_bar.yaml rolled three
faces by the scripted gait (tensegrity_stiffness.simulation.structure_gait): the centre of
mass's path over the faces it rested on, and the contact faces over time.

    python scripts/six_bar_roll_figure.py [--out docs/figures/six_bar_roll.png] [--steps 3]
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np

from tensegrity_stiffness import config
from tensegrity_stiffness.simulation.structure_gait import run_roll
from tensegrity_stiffness.simulation.structure_twin import StructureSimulation
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import Structure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', default='docs/figures/six_bar_roll.png')
    parser.add_argument('--steps', type=int, default=3)
    parser.add_argument('--rate', type=float, default=0.02, help='motor speed, m/s')
    args = parser.parse_args()
    structure = Structure.from_yaml(config.example_config_path('six_bar.yaml'))
    base = solve_structure_equilibrium(structure)
    sim = StructureSimulation(structure, poses=base.poses, rest_length_rate=args.rate)
    faces = [sorted(base.contacts, key=structure.node_names.index)]
    footprints = [structure.node_positions(base.poses)[[structure.node_index(n)
                                                        for n in faces[0]]]]
    record = run_roll(sim, n_steps=args.steps, max_time=15.0 * args.steps)
    for step in record.steps:
        faces.append(list(step.landing_face))
        footprints.append(structure.node_positions(step.landing_poses)[
            [structure.node_index(n) for n in step.landing_face]])
    t = np.array(record.times)
    com = np.array(record.com)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.6), width_ratios=(1, 1.3))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(footprints)))
    # The planned footprints are of the library's equilibria; the twin's path is MuJoCo's.
    for k, (tri, colour) in enumerate(zip(footprints, colours, strict=True)):
        closed = np.vstack([tri, tri[:1]])
        ax.fill(closed[:, 0], closed[:, 1], color=colour, alpha=0.25)
        ax.plot(closed[:, 0], closed[:, 1], color=colour, lw=1)
        ax.annotate(f'face {k}', tri.mean(axis=0)[:2], ha='center', fontsize=8)
    ax.plot(com[:, 0], com[:, 1], 'k-', lw=1.2, label='centre of mass (twin)')
    ax.plot(*com[0, :2], 'go', label='start')
    ax.plot(*com[-1, :2], 'rs', label='end')
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title('6-bar rolled by the gait: path over the support faces', fontsize=10)
    ax.legend(fontsize=8, loc='best')
    order = {}
    labels = []
    index = []
    for contacts in record.contacts:
        key = ' '.join(contacts) if len(contacts) == 3 else None
        if key is not None and key not in order:
            order[key] = len(order)
            labels.append(key)
        index.append(order[key] if key is not None else np.nan)
    bx.plot(t, index, '.', ms=2, color='tab:blue', label='3 contacts: face')
    bx.set_yticks(range(len(labels)), labels, fontsize=7)
    bx.set_xlabel('time [s]')
    bx.set_title('contact faces (3 nodes on the ground) and COM height', fontsize=10)
    h = bx.twinx()
    h.plot(t, com[:, 2] * 1000.0, color='tab:red', lw=1)
    h.set_ylabel('COM height [mm]', color='tab:red')
    phases = record.phases
    for i in range(1, len(phases)):
        if phases[i] != phases[i - 1]:
            bx.axvline(t[i], color='0.7', lw=0.6)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    moved = com[-1, :2] - com[0, :2]
    print(f'{args.out}: {len(record.steps)} steps, faces {faces}, COM moved {moved} m '
          f'({np.linalg.norm(moved):.4f} m) in {t[-1]:.2f} s')


if __name__ == '__main__':
    main()
