"""The structure twin in MuJoCo: settled, it is the library's equilibrium; its sensors are the
structure's own models at its state (lengths and tensions of Structure.evaluate at its poses,
the IMUs against MuJoCo's own accelerometer and gyro sensors); the motors keep their rate
limit; absurd commands and loads are refused with the twin's state kept."""

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.errors import BadRestLengthsError
from tensegrity_stiffness.simulation.structure_twin import (
    StructureSimulation,
    StructureTwinOptions,
    measure_structure,
)
from tensegrity_stiffness.simulation.twin import SensorNoise
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import Structure

mujoco = pytest.importorskip('mujoco')


def example(name: str) -> Structure:
    """A packaged example structure (config/examples)."""
    return Structure.from_yaml(config.example_config_path(name))


def frictionless(structure: Structure) -> Structure:
    document = structure.to_dict()
    document['structure']['ground']['friction'] = 0.0
    return Structure.from_dict(document)


@pytest.fixture(scope='module')
def six_bar():
    return example('six_bar.yaml')


@pytest.fixture(scope='module')
def settled(six_bar):
    """The 6-bar dropped at its equilibrium and settled in MuJoCo (damped against the world to
    settle in a few simulated seconds)."""
    result = solve_structure_equilibrium(six_bar)
    assert result.success
    sim = StructureSimulation(six_bar, poses=result.poses, joint_damping=0.05)
    assert sim.settle(speed=1e-5, max_time=20.0)
    return sim, result


def test_a_settled_six_bar_is_the_library_s_equilibrium(six_bar, settled):
    sim, result = settled
    x = six_bar.node_positions(sim.poses())
    # MuJoCo's friction is a soft velocity constraint: at rest it has relaxed the statically
    # indeterminate tangential contact forces, so the twin rests in the equilibrium on the
    # frictionless ground nearest it (the solver from the twin's poses), up to the contact
    # spheres' sinking (about 0.05 mm under 2 N).
    free = solve_structure_equilibrium(frictionless(six_bar), start=sim.poses())
    assert free.success
    np.testing.assert_allclose(x, six_bar.node_positions(free.poses), atol=1e-4)
    np.testing.assert_allclose(sim.tensions(), free.state.tensions, atol=2e-3)
    assert sim.contact_nodes() == sorted(free.contacts, key=six_bar.node_names.index)
    # And the frictional equilibrium of the same ground to a fraction of a millimetre and of
    # its 3.7 N tensions (its tangential contact forces, 0.15 N, are what MuJoCo relaxed).
    np.testing.assert_allclose(x, six_bar.node_positions(result.poses), atol=3e-4)
    np.testing.assert_allclose(sim.tensions(), result.state.tensions, atol=0.1)
    assert sorted(sim.contact_nodes()) == sorted(result.contacts)


def test_at_rest_strings_weight_and_mujoco_s_contacts_balance_every_bar(six_bar, settled):
    """The library's wrenches at the twin's state, its weights and MuJoCo's contact forces."""
    sim, _ = settled
    T = sim.poses()
    state = sim.evaluate()
    W = state.wrenches + six_bar.gravity_wrenches(T)[0]
    contacts = sim.contact_forces()
    for name, f in contacts.items():
        x = state.node_positions[name]
        W[six_bar.body_index(name.split('.')[0])] += np.r_[f, np.cross(x, f)]
    assert np.abs(W).max() < 1e-3  # N, N m: what the damping of the last 1e-5 m/s leaves
    total = sum(contacts.values())
    np.testing.assert_allclose(total, -sum(b.mass for b in six_bar.bodies) * six_bar.gravity,
                               rtol=1e-4, atol=1e-6)


def test_the_three_bar_settles_on_its_three_bottom_nodes():
    structure = example('three_bar.yaml')
    result = solve_structure_equilibrium(structure)
    sim = StructureSimulation(structure, poses=result.poses, joint_damping=0.05)
    assert sim.settle(speed=1e-5, max_time=20.0)
    assert sorted(sim.contact_nodes()) == sorted(result.contacts)
    np.testing.assert_allclose(structure.node_positions(sim.poses()),
                               structure.node_positions(result.poses), atol=3e-4)


def moving(structure: Structure) -> StructureSimulation:
    """A twin in motion: pushed, its strings changing, off its equilibrium."""
    sim = StructureSimulation(structure, rest_length_rate=0.05)
    sim.push(structure.body_names[0], [0.5, -0.2, 0.3, 0.01, 0.0, -0.02], 0.05)
    rest = structure.rest_lengths.copy()
    rest[:3] *= 0.97
    sim.set_rest_lengths(rest)
    sim.run(0.12)
    return sim


@pytest.mark.parametrize('name', ['three_bar.yaml', 'six_bar.yaml'])
def test_lengths_tensions_and_markers_are_the_structure_s_model_at_the_twin_s_state(name):
    structure = example(name)
    sim = moving(structure)
    assert float(np.abs(sim.data.qvel).max()) > 1e-2  # it moves
    state = structure.evaluate(sim.poses(), sim.rest_lengths)
    np.testing.assert_allclose(sim.string_lengths(), state.lengths, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sim.tensions(), state.tensions, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(sim.slack(), state.slack)
    markers = np.array([state.node_positions[n] for n in sim.marker_names])
    np.testing.assert_allclose(sim.markers(), markers, rtol=0, atol=1e-12)
    # The encoders read the rest lengths in force, MuJoCo's spring lengths.
    np.testing.assert_array_equal(sim.rest_lengths, sim.model.tendon_lengthspring[:, 1])


def with_imu_sensors(sim: StructureSimulation) -> tuple:
    """MuJoCo's own accelerometer and gyro at every IMU bar's origin, on a copy of the twin's
    model at the twin's state (its rest lengths and applied forces)."""
    root = ET.fromstring(sim.mjcf)
    sensors = ET.SubElement(root, 'sensor')
    for name in sim.imu_bodies:
        body = root.find(f".//body[@name='{name}']")
        ET.SubElement(body, 'site', name=f'{name}_imu', pos='0 0 0')
        ET.SubElement(sensors, 'accelerometer', site=f'{name}_imu')
        ET.SubElement(sensors, 'gyro', site=f'{name}_imu')
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding='unicode'))
    model.tendon_lengthspring[:] = sim.model.tendon_lengthspring
    data = mujoco.MjData(model)
    data.qpos[:] = sim.data.qpos
    data.qvel[:] = sim.data.qvel
    data.xfrc_applied[:] = sim.data.xfrc_applied
    sim.imus()  # the twin's acceleration stage at this state; the same warm start for MuJoCo's
    data.qacc_warmstart[:] = sim.data.qacc_warmstart  # contact solver (tolerance 1e-8)
    mujoco.mj_forward(model, data)
    return model, data


@pytest.mark.parametrize('name', ['three_bar.yaml', 'six_bar.yaml'])
def test_each_bar_s_imu_is_mujoco_s_accelerometer_and_gyro(name):
    structure = example(name)
    sim = moving(structure)
    model, data = with_imu_sensors(sim)
    imus = sim.imus()
    assert len(imus) == len(structure.bar_names)
    for k, reading in enumerate(imus):
        accelerometer = data.sensordata[6 * k:6 * k + 3]
        gyro = data.sensordata[6 * k + 3:6 * k + 6]
        scale = max(1.0, float(np.abs(accelerometer).max()))
        np.testing.assert_allclose(reading.specific_force, accelerometer, rtol=0,
                                   atol=1e-9 * scale)
        np.testing.assert_allclose(reading.angular_velocity, gyro, rtol=0, atol=1e-12)
    # And R^T (a - g) of the free joint's own acceleration (a at rest: +g up in the bar frame).
    T = sim.poses()
    i = structure.body_index(sim.imu_bodies[0])
    dof = model.jnt_dofadr[model.body_jntadr[i + 1]]
    a = data.qacc[dof:dof + 3]
    np.testing.assert_allclose(imus[0].specific_force,
                               T[i, :3, :3].T @ (a - structure.gravity), atol=1e-9)


def test_at_rest_the_accelerometers_read_gravity_up(settled):
    sim, _ = settled
    for reading, name in zip(sim.imus(), sim.imu_bodies, strict=True):
        R = sim.poses()[sim.structure.body_index(name), :3, :3]
        np.testing.assert_allclose(R @ reading.specific_force, [0, 0, 9.80665], atol=1e-2)
        assert np.abs(reading.angular_velocity).max() < 1e-4


def test_commanded_rest_lengths_move_at_the_rate_limit(six_bar):
    rate = 0.02
    sim = StructureSimulation(six_bar, rest_length_rate=rate)
    start = six_bar.rest_lengths.copy()
    target = start.copy()
    target[0] -= 0.01    # 0.5 s at 0.02 m/s
    target[5] += 0.004   # 0.2 s
    sim.set_rest_lengths(target)
    dt = sim.options.timestep
    for steps in (1, 50, 150):
        sim.step(steps if steps == 1 else steps - round(sim.time / dt))
        t = sim.time
        expected = start + np.clip(target - start, -rate * t, rate * t)
        np.testing.assert_allclose(sim.rest_lengths, expected, rtol=0, atol=1e-13)  # sums
        assert sim.moving
    sim.run(0.5)
    np.testing.assert_array_equal(sim.rest_lengths, target)  # arrived exactly
    assert not sim.moving
    # Without a rate: at once.
    sim.set_rest_lengths(start, rate=math.inf)
    np.testing.assert_array_equal(sim.rest_lengths, start)


@pytest.mark.parametrize('bad, match', [
    (np.nan, 'rest length of x1a-y2a = nan m is not finite'),
    (1e308, 'x1a-y2a = 1e\\+308 m is outside its range'),
    (5e-324, 'outside its range'),
    (-0.1, 'outside its range'),
    (0.0, 'outside its range'),
])
def test_absurd_rest_lengths_are_refused_naming_the_string(six_bar, bad, match):
    sim = StructureSimulation(six_bar, rest_length_rate=0.01)
    before = sim.target_rest_lengths
    rest = six_bar.rest_lengths.copy()
    rest[0] = bad
    with pytest.raises(BadRestLengthsError, match=match):
        sim.set_rest_lengths(rest)
    np.testing.assert_array_equal(sim.target_rest_lengths, before)
    with pytest.raises(BadRestLengthsError, match='24 values'):
        sim.set_rest_lengths(six_bar.rest_lengths[:5])
    with pytest.raises(ValueError, match='rate'):
        sim.set_rest_lengths(six_bar.rest_lengths, rate=-1.0)


def test_loads_and_pushes(six_bar):
    sim = StructureSimulation(six_bar, max_force=10.0)
    with pytest.raises(ValueError, match=r'load on x1: .*exceeds max_force'):
        sim.apply_loads({'x1': [100.0, 0, 0, 0, 0, 0]})
    with pytest.raises(ValueError, match='finite'):
        sim.apply_loads({'y2': [math.nan, 0, 0, 0, 0, 0]})
    np.testing.assert_array_equal(sim.loads, 0.0)
    with pytest.raises(ValueError, match="no body 'x3'"):
        sim.push('x3', np.zeros(6), 0.1)
    with pytest.raises(ValueError, match='duration'):
        sim.push('x1', np.zeros(6), -1.0)
    # A push of 1 N along x on x1 for 0.02 s: the centre of mass gains 1 N * 0.02 s / 0.6 kg
    # of speed along x, against the strings' internal forces, which cancel.
    structure = Structure.from_dict({**six_bar.to_dict(), 'structure': {
        **six_bar.to_dict()['structure'], 'gravity': None, 'ground': None}})
    free = StructureSimulation(structure, joint_damping=0.0)
    free.push('x1', [1.0, 0, 0, 0, 0, 0], 0.02)
    free.run(0.05)
    masses = np.array([b.mass for b in structure.bodies])
    v = free.velocities()
    com_speed = masses @ (v[:, :3] + np.cross(v[:, 3:], np.zeros(3))) / masses.sum()
    np.testing.assert_allclose(com_speed, [0.02 / 0.6, 0, 0], atol=2e-3)
    # A load about the world origin equals the library's convention: [f; x x f] of f at x.
    free.apply_loads({'x2': np.r_[[0, 0, 1.0], np.cross(free.poses()[1, :3, 3], [0, 0, 1.0])]})
    c = free.data.xipos[free.model.body('x2').id]
    np.testing.assert_allclose(free.data.xfrc_applied[free.model.body('x2').id],
                               [0, 0, 1.0, *(np.cross(free.poses()[1, :3, 3] - c, [0, 0, 1.0]))],
                               atol=1e-12)


def test_measurements_are_seeded_and_noisy_as_configured(six_bar):
    sim = StructureSimulation(six_bar)
    noise = SensorNoise(lengths=1e-3, tensions=0.1, gyro=0.01, accelerometer=0.1,
                        encoders=1e-4, markers=2e-3)
    a = measure_structure(sim, noise, np.random.default_rng(7), markers=True)
    b = measure_structure(sim, noise, np.random.default_rng(7), markers=True)
    np.testing.assert_array_equal(a.lengths, b.lengths)
    np.testing.assert_array_equal(a.markers, b.markers)
    exact = measure_structure(sim, SensorNoise(), np.random.default_rng(7))
    assert exact.markers is None
    np.testing.assert_array_equal(exact.lengths, sim.string_lengths())
    np.testing.assert_array_equal(exact.encoders, sim.rest_lengths)
    draws = np.array([measure_structure(sim, noise, np.random.default_rng(s), markers=True
                                        ).markers - sim.markers() for s in range(40)])
    assert 0.8 * 2e-3 < draws.std() < 1.2 * 2e-3
    with pytest.raises(ValueError, match='encoders'):
        SensorNoise(encoders=-1.0)


def test_options_are_checked(six_bar):
    with pytest.raises(ValueError, match='unknown structure twin options'):
        StructureSimulation(six_bar, timestpe=1e-3)
    with pytest.raises(ValueError, match='integrator'):
        StructureTwinOptions(integrator='RK4')
    with pytest.raises(ValueError, match='rest_length_range'):
        StructureTwinOptions(rest_length_range=(0.2, 0.1))
    document = six_bar.to_dict()
    document['structure']['force_law'] = 'paper'
    with pytest.raises(ValueError, match="Hooke's law"):
        StructureSimulation(Structure.from_dict(document))
