"""Form-finding against the published forms: the force density method finds the regular p-prism at
90 - 180/p degrees from a start at any twist (Schek 1974; Tibert & Pellegrino 2003); kinematic
form-finding lengthens the unit-string p-prism's bars to sqrt(1 + 1/sin(pi/p)) (p = 3: 1.4679,
Tibert & Pellegrino's triangular prism; p = 6: sqrt(3), the flat limit) and the equal-string
6-bar's to sqrt(8/3); rest lengths designed for a target shape hold it (wrenches zero) with
tensions in the band."""

import math

import numpy as np
import pytest
from structure_fixtures import mixed_document, perturbed

from tensegrity_stiffness.mechanics.dynamics import LinkInertia
from tensegrity_stiffness.structures import templates
from tensegrity_stiffness.structures.analysis import Framework, analyse_framework, stress_matrix
from tensegrity_stiffness.structures.form_finding import (
    design_rest_lengths_for_shape,
    force_density_form,
    kinematic_form,
    string_wrench_matrix,
)
from tensegrity_stiffness.structures.structure import Structure

PRISMS = (3, 4, 5, 6)
#: Twist agreement of the kinematic search (SLSQP stops at ftol 1e-12 on the squared length,
#: so the positions are good to about its square root).
KINEMATIC_ANGLE_TOL = 1e-6
#: Agreement of the kinematic bar lengths with the closed forms.
KINEMATIC_LENGTH_RTOL = 1e-9


def prism_densities(p: int) -> np.ndarray:
    ring, vertical, bar = templates.prism_force_densities(p)
    return np.array([ring] * 2 * p + [vertical] * p + [bar] * p)


def twist_of(X: np.ndarray, p: int) -> float:
    """The top polygon's turn against the bottom one (rad, in [0, 2 pi / p))."""
    bottom, top = X[:p] - X[:p].mean(axis=0), X[p:] - X[p:].mean(axis=0)
    turn = math.atan2(top[0, 1], top[0, 0]) - math.atan2(bottom[0, 1], bottom[0, 0])
    return turn % (2 * math.pi)


def affine_fit_residual(X: np.ndarray, Y: np.ndarray) -> float:
    """Largest residual of the best affine map taking ``Y`` onto ``X``."""
    H = np.hstack([Y, np.ones((Y.shape[0], 1))])
    M = np.linalg.lstsq(H, X, rcond=None)[0]
    return float(np.abs(H @ M - X).max())


@pytest.mark.parametrize('p', PRISMS)
@pytest.mark.parametrize('start_twist', [0.2, 0.9, 1.4])
def test_force_densities_give_the_prism_at_its_twist_from_any_start(p, start_twist):
    layout = templates.prism_layout(p, 1.0, 1.5, twist=start_twist)
    result = force_density_form(layout.framework(), prism_densities(p), start=layout.positions)
    X = result.positions
    assert result.info['nullity'] == 4 and result.info['residual'] < 1e-13
    assert twist_of(X, p) == pytest.approx(templates.prism_twist(p), abs=1e-12)
    exact = templates.prism_layout(p, 1.0, 1.5).positions
    assert affine_fit_residual(X, exact) < 1e-12
    a = analyse_framework(result.framework)  # carries q l: a self-stress of the form
    assert a.residual < 1e-12 and a.super_stable


def test_force_densities_without_start_give_an_affine_image():
    p = 5
    layout = templates.prism_layout(p, 1.0, 1.0)
    result = force_density_form(layout.framework(), prism_densities(p))
    X = result.positions
    np.testing.assert_allclose(X.mean(axis=0), 0.0, atol=1e-14)
    np.testing.assert_allclose(X.T @ X, np.eye(3), atol=1e-12)  # the orthonormal gauge
    assert affine_fit_residual(X, layout.positions) < 1e-12


def test_force_densities_with_supports_solve_the_net():
    """A net: node c on four anchors with q = 1, 1, 2, 2 sits at their q-weighted mean
    (Schek's linear equations); node d on c and one anchor follows."""
    anchors = np.array([[0, 0, 0], [1, 0, 0.5], [1, 1, 0], [0, 1, 1.0]])
    X0 = np.vstack([anchors, [[0.5, 0.5, 0.2], [0.3, 0.8, 0.4]]])  # free: any start
    members = [(4, 0), (4, 1), (4, 2), (4, 3), (5, 4), (5, 2)]
    fw = Framework.build(('w0', 'w1', 'w2', 'w3', 'c', 'd'), X0 + 0.0, members,
                         tuple(f'm{k}' for k in range(6)), [False] * 6,
                         [True] * 4 + [False] * 2)
    q = np.array([1.0, 1.0, 2.0, 2.0, 1e-9, 1.0])
    result = force_density_form(fw, q)
    X = result.positions
    Omega = stress_matrix(6, fw.members, q)
    np.testing.assert_allclose((Omega @ X)[4:], 0.0, atol=1e-12)
    np.testing.assert_allclose(X[:4], anchors, atol=0)
    qc = q[:4]
    expected_c = (qc @ anchors + q[4] * X[5]) / (qc.sum() + q[4])
    np.testing.assert_allclose(X[4], expected_c, atol=1e-12)
    np.testing.assert_allclose(result.framework.forces, q * result.framework.lengths)


def test_force_densities_that_hold_no_form_are_refused():
    layout = templates.prism_layout(3, 1.0, 1.0)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match='nullity 1 < 4'):
        force_density_form(layout.framework(), rng.uniform(0.5, 2.0, size=12))
    with pytest.raises(ValueError, match='densities must be 12'):
        force_density_form(layout.framework(), np.ones(3))
    anchored = Framework.build(('w', 'a', 'b'), np.eye(3), [(0, 1), (1, 2)], ('m0', 'm1'),
                               [False, False], [True, False, False])
    with pytest.raises(ValueError, match='singular'):
        force_density_form(anchored, [1.0, 0.0])


@pytest.mark.parametrize('p', (3, 4, 5))  # p = 6 is flat: its own test below
def test_kinematic_form_finding_of_the_unit_string_prism(p):
    """Strings of unit length, bars lengthened to their maximum: the bar of Tibert & Pellegrino
    (p = 3: sqrt(1 + 2/sqrt 3) = 1.4679), the twist 90 - 180/p, and one self-stress."""
    side = 2.0 * math.sin(math.pi / p)
    start = templates.prism_layout(p, 1.0 / side, 1.0, twist=templates.prism_twist(p) + 0.3)
    result = kinematic_form(start.framework(), string_lengths=np.ones(3 * p))
    assert result.success, result.message
    expected = math.sqrt(1.0 + 1.0 / math.sin(math.pi / p))
    assert result.info['bar_length'] == pytest.approx(expected, rel=KINEMATIC_LENGTH_RTOL)
    if p == 3:
        assert round(result.info['bar_length'], 4) == 1.4679
    fw = result.framework
    np.testing.assert_allclose(fw.lengths[:3 * p], 1.0, rtol=1e-12)
    assert twist_of(fw.positions, p) == pytest.approx(templates.prism_twist(p),
                                                      abs=KINEMATIC_ANGLE_TOL)
    a = analyse_framework(fw)
    assert a.self_stresses == 1 and a.prestress_stable


def test_kinematic_form_finding_of_the_unit_string_hexagonal_prism_is_flat():
    """p = 6: the bar sqrt(1 + 1/sin(pi/6)) = sqrt(3) = 1.7321 at the twist 60 degrees. The
    unit-string prism's height h^2 = 1 - (2 R sin(alpha/2))^2 (R = 1 / (2 sin(pi/p)) the
    polygons' radius, alpha the twist) is zero at p = 6: the form is the flat hexagram (the bar
    the chord of 120 degrees of the unit hexagon), with one self-stress and an unfolding out of
    the plane that no prestress stiffens."""
    p = 6
    side = 2.0 * math.sin(math.pi / p)
    radius = 1.0 / side
    alpha = templates.prism_twist(p)
    assert 1.0 - (2.0 * radius * math.sin(alpha / 2.0)) ** 2 == pytest.approx(0.0, abs=1e-15)
    start = templates.prism_layout(p, radius, 1.0, twist=alpha + 0.3)
    result = kinematic_form(start.framework(), string_lengths=np.ones(3 * p))
    assert result.success, result.message
    assert result.info['bar_length'] == pytest.approx(math.sqrt(3.0), rel=KINEMATIC_LENGTH_RTOL)
    assert round(result.info['bar_length'], 4) == 1.7321
    fw = result.framework
    np.testing.assert_allclose(fw.lengths[:3 * p], 1.0, rtol=1e-12)
    assert twist_of(fw.positions, p) == pytest.approx(alpha, abs=KINEMATIC_ANGLE_TOL)
    # Flat: the lengths change as h^2, so SLSQP finds h to about the square root of its
    # precision (measured 9e-6).
    X = fw.positions
    assert abs(X[p:, 2].mean() - X[:p, 2].mean()) < 1e-4
    a = analyse_framework(fw)
    assert a.self_stresses == 1 and a.strings_pull
    assert not a.prestress_stable and abs(a.prestress_stiffness[0]) < 1e-6


def test_kinematic_form_finding_of_the_equal_string_six_bar():
    """Equal unit strings, the six bars lengthened together: sqrt(8/3) (the expanded
    octahedron) from a start off it."""
    layout = templates.six_bar_layout(1.0)
    rng = np.random.default_rng(4)
    fw = layout.framework().with_positions(layout.positions
                                           + rng.normal(scale=0.02, size=(12, 3)))
    result = kinematic_form(fw, string_lengths=np.ones(24))
    assert result.success, result.message
    assert result.info['bar_length'] == pytest.approx(math.sqrt(8.0 / 3.0), rel=1e-8)
    assert analyse_framework(result.framework).super_stable


def test_kinematic_form_finding_names_a_missing_bar():
    fw = templates.prism_layout(3).framework()
    with pytest.raises(ValueError, match="no bar 'bar9'"):
        kinematic_form(fw, lengthen=['bar9'])
    with pytest.raises(ValueError, match='string_lengths must be 9'):
        kinematic_form(fw, string_lengths=[1.0])


@pytest.mark.parametrize('layout', [templates.prism_layout(3, 0.1, 0.2),
                                    templates.six_bar_layout(0.3)], ids=['prism', 'six-bar'])
@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_designed_rest_lengths_hold_the_shape(layout, force_law):
    document = templates.structure_document_of_layout(layout, force_law=force_law)
    structure = Structure.from_dict(document)
    design = design_rest_lengths_for_shape(structure, t_min=2.0, t_max=10.0)
    assert design.success, design.message
    assert np.all(design.tensions >= 2.0 - 1e-12) and np.all(design.tensions <= 10.0 + 1e-12)
    state = structure.evaluate(rest_lengths=design.rest_lengths)
    assert np.abs(state.wrenches).max() < 1e-11
    np.testing.assert_allclose(state.tensions, design.tensions, rtol=1e-10)
    np.testing.assert_allclose(state.bar_forces, design.bar_forces, rtol=1e-9)


def test_a_band_the_self_stress_cannot_fit_is_reported():
    """The 3-prism's vertical strings carry 2.07 times the polygons' tension here: no
    self-stress fits in [2, 3] N."""
    structure = Structure.from_dict(templates.structure_document_of_layout(
        templates.prism_layout(3, 0.1, 0.2)))
    design = design_rest_lengths_for_shape(structure, t_min=2.0, t_max=3.0)
    assert not design.success and 'no string tensions hold this shape' in design.message
    with pytest.raises(ValueError, match='tension band'):
        design_rest_lengths_for_shape(structure, t_min=3.0, t_max=2.0)


def test_design_carries_the_weight_of_a_hung_bar():
    """A bar hung from two world anchors: each string carries half its weight."""
    m, g = 0.4, 9.81
    doc = {'structure': {
        'gravity': [0.0, 0.0, -g],
        'bodies': [{'name': 'bar', 'type': 'bar', 'length': 0.2, 'mass': m,
                    'pose': [0.0, 0.0, 0.0, 0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5)]}],
        'world_nodes': {'w0': [-0.1, 0.0, 0.3], 'w1': [0.1, 0.0, 0.3]},
        'strings': [{'name': 's0', 'from': 'world.w0', 'to': 'bar.a', 'stiffness': 100.0,
                     'rest_length': 0.2},
                    {'name': 's1', 'from': 'world.w1', 'to': 'bar.b', 'stiffness': 100.0,
                     'rest_length': 0.2}]}}
    structure = Structure.from_dict(doc)
    X = structure.node_positions(structure.transforms())
    assert X[structure.node_index('bar.a'), 0] == pytest.approx(-0.1)  # under w0
    design = design_rest_lengths_for_shape(structure, t_min=0.1, t_max=10.0)
    assert design.success, design.message
    np.testing.assert_allclose(design.tensions, 0.5 * m * g, rtol=1e-12)
    np.testing.assert_allclose(design.bar_forces, 0.0, atol=1e-12)


def test_the_string_wrench_matrix_gives_the_evaluated_wrenches():
    structure = Structure.from_dict(mixed_document())
    T = perturbed(structure.start_poses(), np.random.default_rng(5))
    state = structure.evaluate(T)
    G = string_wrench_matrix(structure, T)
    np.testing.assert_allclose(G @ state.tensions, state.wrenches.reshape(-1), atol=1e-12)


def test_design_holds_the_joint_s_link_under_its_weight():
    """A general body: the default joint's link 2 (12 strings, link 1 fixed) given a mass and
    gravity, at its unloaded pose: the designed rest lengths hold it with its weight."""
    from support import REPO

    from tensegrity_stiffness.mechanics.joint import JointModel

    model = JointModel.from_yaml(REPO / 'config' / 'default_joint.yaml')
    document = Structure.from_joint(model, inertia=LinkInertia(mass=0.05)).to_dict()
    document['structure']['gravity'] = [0.0, -9.81, 0.0]
    structure = Structure.from_dict(document)
    design = design_rest_lengths_for_shape(structure, t_min=0.2, t_max=3.0)
    assert design.success, design.message
    T = structure.start_poses()
    state = structure.evaluate(T, rest_lengths=design.rest_lengths)
    weights = structure.gravity_wrenches(T)[0]
    np.testing.assert_allclose((state.wrenches + weights)[1], 0.0, atol=1e-12)
    assert np.all(state.tensions >= 0.2 - 1e-12) and np.all(state.tensions <= 3.0 + 1e-12)
    assert abs(weights[1, 1]) == pytest.approx(0.05 * 9.81)
    # Its strings stretch at most 0.02 m at 77 N/m (lmax - l0 kept): 1.54 N is their cap.
    assert np.all(state.tensions <= 77.0 * 0.02) and not state.saturated.any()
    short = design_rest_lengths_for_shape(structure, t_min=2.0, t_max=3.0)
    assert not short.success and 'cannot carry t_min = 2 N' in short.message


def test_the_joint_design_with_a_stiffness_objective_through_the_structure():
    """A structure of the joint's form runs the joint's own design: the same rest lengths as
    mechanics.design on the config's model, and under the link's weight the designed rest
    lengths hold the structure with K_c near the target."""
    from support import REPO

    from tensegrity_stiffness.mechanics.design import design_rest_lengths
    from tensegrity_stiffness.mechanics.joint import JointModel
    from tensegrity_stiffness.structures.form_finding import design_joint_stiffness

    model = JointModel.from_yaml(REPO / 'config' / 'default_joint.yaml')
    target = model.evaluate(model.initial_screw).cartesian_stiffness
    structure = Structure.from_joint(model, inertia=LinkInertia(mass=0.05))
    ours = design_joint_stiffness(structure, target, t_min=0.05, t_max=1.5)
    direct = design_rest_lengths(model, model.initial_screw, None, 0.05, 1.5, target)
    assert ours.success and direct.success
    assert ours.stiffness_error < 1e-12  # the config's own K_c is reachable exactly
    np.testing.assert_allclose(ours.rest_lengths, direct.rest_lengths, rtol=1e-12)
    document = structure.to_dict()
    document['structure']['gravity'] = [0.0, -9.81, 0.0]
    heavy = Structure.from_dict(document)
    design = design_joint_stiffness(heavy, target, t_min=0.05, t_max=1.5)
    assert design.success, design.message
    T = heavy.start_poses()
    state = heavy.evaluate(T, rest_lengths=design.rest_lengths)
    np.testing.assert_allclose((state.wrenches + heavy.gravity_wrenches(T)[0])[1], 0.0,
                               atol=1e-10)
    assert design.stiffness_error < 0.05  # measured 0.025 under 0.05 kg
    with pytest.raises(ValueError, match='two bodies, one fixed and one free'):
        design_joint_stiffness(Structure.from_dict(templates.prism_document(3)), target)


def test_kinematic_form_finding_with_the_bottom_fixed():
    """Supports instead of the gauge: the unit-string 3-prism with its bottom triangle held
    reaches the same bar, 1.4679."""
    p = 3
    side = 2.0 * math.sin(math.pi / p)
    start = templates.prism_layout(p, 1.0 / side, 1.0, twist=templates.prism_twist(p) + 0.3)
    fw = start.framework()
    held = Framework.build(fw.node_names, fw.positions, fw.members.tolist(), fw.member_names,
                           fw.is_bar.tolist(), [True] * p + [False] * p)
    result = kinematic_form(held, string_lengths=np.ones(3 * p))
    assert result.success, result.message
    assert result.info['bar_length'] == pytest.approx(math.sqrt(1.0 + 2.0 / math.sqrt(3.0)),
                                                      rel=KINEMATIC_LENGTH_RTOL)
    np.testing.assert_array_equal(result.positions[:p], fw.positions[:p])
