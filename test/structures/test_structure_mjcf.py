"""The MuJoCo export of structures, loaded and stepped in the real engine: a settled MuJoCo
structure matches solve_structure_equilibrium (a bar hanging from world anchors; the 6-bar
dropped onto a ground with friction), and the model is what the structure says."""

import numpy as np
import pytest
from structure_fixtures import SIXBAR, example, mixed_document
from test_structure_equilibrium import on_the_ground
from test_structure_modes import hanging_bar

from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.mjcf import StructureMjcfOptions, structure_mjcf
from tensegrity_stiffness.structures.structure import Structure

mujoco = pytest.importorskip('mujoco')


def settle(structure, poses, seconds, damping):
    """Node positions after ``seconds`` of MuJoCo from ``poses`` at rest, with free-joint
    damping ``damping``; and the largest speed left."""
    xml = structure_mjcf(structure, poses, StructureMjcfOptions(joint_damping=damping))
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    for _ in range(round(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
    x = {}
    for name in structure.node_names:
        x[name] = data.site_xpos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)].copy()
    return x, float(np.abs(data.qvel).max())


def test_the_model_has_the_structure_s_bodies_strings_and_ground():
    document = mixed_document()
    document['structure']['ground'] = {'normal': [0, 0, 1], 'height': -0.5, 'friction': 0.6}
    structure = Structure.from_dict(document)
    model = mujoco.MjModel.from_xml_string(structure_mjcf(structure))
    assert model.nbody == 1 + structure.n_bodies
    assert model.njnt == structure.n_bodies  # a free joint each
    assert model.ntendon == structure.n_strings
    np.testing.assert_allclose(model.tendon_stiffness, structure.k)
    np.testing.assert_allclose(model.tendon_lengthspring[:, 1], structure.rest_lengths)
    for i, body in enumerate(structure.bodies):
        np.testing.assert_allclose(model.body_mass[i + 1], body.mass)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    state = structure.evaluate()
    np.testing.assert_allclose(data.ten_length, state.lengths, rtol=1e-12)


def test_the_paper_law_and_massless_bodies_are_refused():
    with pytest.raises(ValueError, match="Hooke's law"):
        structure_mjcf(Structure.from_dict(mixed_document('paper')))
    document = example(SIXBAR).to_dict()
    document['structure']['bodies'][0].update(mass=0.0, inertia=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"\['x_up'\] have none"):
        structure_mjcf(Structure.from_dict(document))


def test_a_settled_hanging_bar_is_the_equilibrium():
    structure = hanging_bar()
    result = solve_structure_equilibrium(structure)
    x, speed = settle(structure, None, 5.0, 0.5)
    assert speed < 1e-5
    for name in structure.node_names:
        np.testing.assert_allclose(x[name], result.state.node_positions[name], atol=1e-7)


def test_the_six_bar_dropped_on_the_ground_settles_into_the_equilibrium():
    """From the pose where its face first touches, MuJoCo (soft contacts: the spheres sink by
    about 0.05 mm) and the solver agree to a fraction of a millimetre on a 1 m structure."""
    structure, start = on_the_ground(0.8)
    dropped = start.copy()
    dropped[:, 2, 3] -= structure.node_positions(start)[:, 2].min()
    result = solve_structure_equilibrium(structure, start=dropped)
    assert result.success
    x, speed = settle(structure, dropped, 5.0, 0.3)
    assert speed < 1e-3
    for name in structure.node_names:
        np.testing.assert_allclose(x[name], result.state.node_positions[name], atol=1e-3)
    # The same nodes carry it.
    assert sorted(n for n in structure.node_names if x[n][2] < 1e-3) == sorted(result.contacts)


def test_export_mjcf_takes_a_structure_file(tmp_path, capsys):
    from structure_fixtures import HERE, SIXBAR

    from tensegrity_stiffness.cli import main

    out = tmp_path / 'sixbar.xml'
    assert main(['export-mjcf', '--structure', str(HERE / SIXBAR), '--out', str(out)]) == 0
    model = mujoco.MjModel.from_xml_path(str(out))
    assert model.ntendon == 24 and model.nbody == 7
    capsys.readouterr()
    # The help names what it exports: the joint, the spine or a structure.
    assert main(['--help']) == 0
    assert 'MuJoCo model (MJCF) of the joint, the spine or a structure' in ' '.join(
        capsys.readouterr().out.split())
    assert main(['export-mjcf', '--help']) == 0
    assert 'or with --structure of a structure file' in ' '.join(capsys.readouterr().out.split())
