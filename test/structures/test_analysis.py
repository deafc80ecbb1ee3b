"""The pin-jointed analysis against what others published: the regular p-prisms (one self-stress,
2p - 5 mechanisms, the force densities of Connelly & Terrell / Tibert & Pellegrino, super
stable), the expanded octahedron (strut / string sqrt(8/3), bars L/2 apart, q = -3/2), a node
held by coplanar strings (Calladine's first-order mechanism stiffened by prestress), and the
equilibrium matrix against central differences of the member lengths."""

import math

import numpy as np
import pytest
from structure_fixtures import mixed_document

from tensegrity_stiffness.structures import templates
from tensegrity_stiffness.structures.analysis import (
    Framework,
    analyse,
    analyse_framework,
    body_counts,
    directions_on_conic_at_infinity,
    equilibrium_matrix,
    free_coordinates,
    product_forces,
    remaining_rigid_motions,
    stress_matrix,
)
from tensegrity_stiffness.structures.structure import Structure

PRISMS = (3, 4, 5, 6)
#: Agreement of closed forms with the SVD's self-stress (a few hundred eps).
CLOSED_FORM_RTOL = 1e-12


def prism_structure(p: int, **kwargs) -> Structure:
    return Structure.from_dict(templates.structure_document_of_layout(
        templates.prism_layout(p, 0.1, 0.25), **kwargs))


@pytest.mark.parametrize('p', PRISMS)
def test_p_prism_counts_force_densities_and_super_stability(p):
    s = prism_structure(p)
    assert np.abs(s.evaluate().wrenches).max() < 1e-12  # the template is an equilibrium
    a = analyse(s)
    # Pellegrino & Calladine: m - s = 3j - b - 6 with j = 2p nodes, b = 4p members
    # (p bars, 3p strings) gives m = 2p - 5 for the one self-stress.
    assert (a.self_stresses, a.mechanisms, a.rigid_motions) == (1, 2 * p - 5, 6)
    assert a.rank == 4 * p - 1
    q = a.force_densities
    ring, vertical, bar = templates.prism_force_densities(p)
    scale = q['bottom_0'] / ring
    for i in range(p):
        for name, expected in ((f'bottom_{i}', ring), (f'top_{i}', ring),
                               (f'vertical_{i}', vertical), (f'bar{i}', bar)):
            assert q[name] == pytest.approx(expected * scale, rel=CLOSED_FORM_RTOL)
    assert a.residual < 1e-12
    assert a.stress_psd and a.stress_nullity == 4
    assert not a.conic_at_infinity
    assert a.super_stable and a.prestress_stable
    assert a.prestress_stiffness.shape == (2 * p - 5,) and a.prestress_stiffness[0] > 0.0


def test_the_3_prism_force_densities_are_1_sqrt3_minus_sqrt3():
    """Tibert & Pellegrino 2003 (the force density method, the triangular prism)."""
    assert templates.prism_force_densities(3) == pytest.approx((1.0, math.sqrt(3), -math.sqrt(3)))


@pytest.mark.parametrize('p', PRISMS)
def test_a_prism_off_its_twist_has_no_self_stress(p):
    """Only at 90 - 180/p degrees does the prism carry a prestress: elsewhere m - s = 2p - 6
    with s = 0."""
    layout = templates.prism_layout(p, 0.1, 0.25, twist=templates.prism_twist(p) + 0.2)
    a = analyse_framework(layout.framework())
    assert (a.self_stresses, a.mechanisms) == (0, 2 * p - 6)
    with pytest.raises(ValueError, match='0 self-stresses'):
        templates.self_stress_tensions(layout, 1.0)


@pytest.mark.parametrize('p', PRISMS)
def test_the_equilibrium_twist_is_90_minus_180_over_p(p):
    """The self-stress appears exactly at the twist: the smallest singular value of the
    equilibrium matrix vanishes at alpha = pi/2 - pi/p and nowhere else in (0, pi)."""
    alphas = np.linspace(0.05, math.pi - 0.05, 301)

    def smallest(alpha):
        lay = templates.prism_layout(p, 0.1, 0.25, twist=alpha)
        return np.linalg.svd(equilibrium_matrix(lay.positions, lay.framework().members),
                             compute_uv=False)[-1]

    values = np.array([smallest(a) for a in alphas])
    away = np.abs(alphas - templates.prism_twist(p)) > 0.05
    assert values[away].min() > 1e-3
    assert smallest(templates.prism_twist(p)) < 1e-14


def test_six_bar_geometry_counts_and_force_densities():
    L = 0.3
    layout = templates.six_bar_layout(L)
    fw = layout.framework()
    n_s = len(layout.strings)
    assert (len(layout.node_names), n_s, len(layout.bars)) == (12, 24, 6)
    strings, bars = fw.lengths[:n_s], fw.lengths[n_s:]
    np.testing.assert_allclose(bars / strings.mean(), math.sqrt(8.0 / 3.0), rtol=1e-14)
    np.testing.assert_allclose(strings, strings[0], rtol=1e-14)
    X = layout.positions
    for first, second in (('x1', 'x2'), ('y1', 'y2'), ('z1', 'z2')):
        i, j = layout.bars[first][0], layout.bars[second][0]
        gap = np.linalg.norm(X[i] - X[j])  # parallel bars: node to node across the pair
        assert gap == pytest.approx(L / 2.0, rel=1e-14)
    s = Structure.from_dict(templates.structure_document_of_layout(layout))
    a = analyse(s)
    # j = 12, b = 30: m - s = 36 - 30 - 6 = 0, with one self-stress and one mechanism.
    assert (a.self_stresses, a.mechanisms) == (1, 1)
    q = a.density_vector
    np.testing.assert_allclose(q[n_s:] / q[:n_s].mean(), -1.5, rtol=1e-12)
    np.testing.assert_allclose(q[:n_s], q[0], rtol=1e-12)
    assert a.super_stable and a.prestress_stable and a.stress_nullity == 4


def _star(kind_bar: bool, sign: float) -> Framework:
    """A node at the origin joined to three fixed anchors in the z = 0 plane."""
    angles = 2.0 * math.pi * np.arange(3) / 3.0
    anchors = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(3)])
    X = np.vstack([np.zeros(3), anchors])
    return Framework.build(('c', 'w0', 'w1', 'w2'), X, [(0, 1), (0, 2), (0, 3)],
                           ('m0', 'm1', 'm2'), [kind_bar] * 3, [False, True, True, True],
                           sign * np.ones(3))


def test_a_node_on_three_coplanar_strings_is_stiffened_by_its_prestress():
    """Calladine 1978: 3 members in a plane hold the node with s = 1 and one first-order
    mechanism out of the plane; tension stiffens it (K = sum t / l = 3 t), compression does not.
    """
    pulled = analyse_framework(_star(False, 2.0))
    assert (pulled.self_stresses, pulled.mechanisms, pulled.rigid_motions) == (1, 1, 0)
    np.testing.assert_allclose(pulled.mechanism_basis[:, 0] ** 2, [0, 0, 1], atol=1e-24)
    assert pulled.prestress_stiffness == pytest.approx([6.0], rel=1e-14)
    assert pulled.prestress_stable and pulled.super_stable is None
    pushed = analyse_framework(_star(True, -2.0))
    assert pushed.strings_pull and not pushed.prestress_stable
    assert pushed.prestress_stiffness == pytest.approx([-6.0], rel=1e-14)
    wrong = analyse_framework(_star(False, -2.0))  # strings that push
    assert not wrong.strings_pull and not wrong.prestress_stable


def test_equilibrium_matrix_is_the_transpose_of_the_length_jacobian():
    """``e = A' d``: central differences of the member lengths."""
    layout = templates.six_bar_layout(0.3)
    fw = layout.framework()
    A = equilibrium_matrix(fw.positions, fw.members)
    h = 1e-6
    J = np.zeros_like(A.T)
    for c in range(A.shape[0]):
        dX = np.zeros(A.shape[0])
        dX[c] = h
        plus = fw.with_positions(fw.positions + dX.reshape(-1, 3)).lengths
        minus = fw.with_positions(fw.positions - dX.reshape(-1, 3)).lengths
        J[:, c] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(A.T, J, atol=1e-9)


def test_stress_matrix_is_the_hessian_of_the_stress_energy():
    """``Omega (x) I`` is the Hessian of ``1/2 sum q_k l_k^2``: its gradient is ``Omega X``,
    and ``Omega X = 0`` for a self-stress."""
    rng = np.random.default_rng(3)
    layout = templates.prism_layout(4, 0.1, 0.2)
    fw = layout.framework()
    q = rng.normal(size=fw.members.shape[0])
    Omega = stress_matrix(8, fw.members, q)
    X = rng.normal(size=(8, 3))

    def energy(Y):
        i, j = fw.members.T
        return 0.5 * np.sum(q * np.sum((Y[i] - Y[j]) ** 2, axis=1))

    h = 1e-6
    grad = np.zeros_like(X)
    for n in range(8):
        for c in range(3):
            dX = np.zeros_like(X)
            dX[n, c] = h
            grad[n, c] = (energy(X + dX) - energy(X - dX)) / (2 * h)
    np.testing.assert_allclose(Omega @ X, grad, atol=1e-8)
    t = templates.self_stress_tensions(layout, 1.0)
    a = analyse_framework(fw.with_forces(t))
    np.testing.assert_allclose(a.stress_matrix @ fw.positions, 0.0, atol=1e-14)


def test_rigid_motions_and_conics_at_infinity():
    line = np.column_stack([np.arange(4.0), np.zeros(4), np.zeros(4)])
    assert remaining_rigid_motions(line, np.zeros(4, dtype=bool)).shape[1] == 5
    cloud = np.random.default_rng(1).normal(size=(5, 3))
    assert remaining_rigid_motions(cloud, np.zeros(5, dtype=bool)).shape[1] == 6
    pinned = np.array([True, False, False, False, False])
    assert remaining_rigid_motions(cloud, pinned).shape[1] == 3  # rotations about the pin
    # Directions along the three axes lie on the conic xy = 0 at infinity; six generic do not.
    assert directions_on_conic_at_infinity(np.eye(3))
    assert not directions_on_conic_at_infinity(np.random.default_rng(2).normal(size=(6, 3)))


def test_free_general_bodies_are_refused_by_name():
    s = Structure.from_dict(mixed_document())
    with pytest.raises(ValueError, match="'hub' is a free body of 3 nodes"):
        analyse(s)


def test_bad_frameworks_name_the_field():
    with pytest.raises(ValueError, match='positions'):
        Framework.build(('a', 'b'), np.zeros((3, 3)), [(0, 1)], ('m',), [False])
    with pytest.raises(ValueError, match='zero length'):
        Framework.build(('a', 'b'), np.zeros((2, 3)), [(0, 1)], ('m',), [False])
    with pytest.raises(ValueError, match='forces'):
        Framework.build(('a', 'b'), np.eye(3)[:2], [(0, 1)], ('m',), [False], forces=[1, 2])


@pytest.mark.parametrize('p', PRISMS)
def test_body_counts_equal_the_pin_jointed_counts_for_bars(p):
    """The rigid-body model with the bar spins and rigid motions removed counts what the
    pin-jointed framework counts (a bar's balance makes its force axial)."""
    s = prism_structure(p)
    counts = body_counts(s)
    a = analyse(s)
    assert (counts.self_stresses, counts.mechanisms) == (a.self_stresses, a.mechanisms)
    assert (counts.rigid_motions, counts.spins) == (6, p)
    six = Structure.from_dict(templates.six_bar_document())
    assert (body_counts(six).self_stresses, body_counts(six).mechanisms) == (1, 1)


def test_body_counts_of_the_joint():
    """The default joint: link 2 on 12 strings, its 6 equations of full rank: 6 self-stresses
    of the strings, no mechanism, nothing to remove (link 1 is fixed)."""
    from support import REPO

    from tensegrity_stiffness import config

    document = config.load_yaml(REPO / 'config' / 'default_joint.yaml')
    s = Structure.from_dict(templates.config_structure_document(document))
    counts = body_counts(s)
    assert (counts.rank, counts.self_stresses, counts.mechanisms) == (6, 6, 0)
    assert (counts.rigid_motions, counts.spins) == (0, 0)


def test_a_bar_hung_from_world_anchors_has_supports_and_stiffened_swings():
    """World nodes are supports: the bar's two free ends (6 coordinates) on two strings and the
    bar (rank 3): no self-stress, 3 mechanisms (the swings), each stiffened by the strings'
    tension t / l (the pendulum's restoring stiffness; the swing of the whole about the
    anchors' line counts: with supports no rigid motion is removed)."""
    doc = {'structure': {
        'gravity': [0.0, 0.0, -9.81],
        'bodies': [{'name': 'bar', 'type': 'bar', 'length': 0.2, 'mass': 0.4,
                    'pose': [0.0, 0.0, 0.0, 0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5)]}],
        'world_nodes': {'w0': [-0.1, 0.0, 0.3], 'w1': [0.1, 0.0, 0.3]},
        'strings': [{'name': 's0', 'from': 'world.w0', 'to': 'bar.a', 'stiffness': 100.0,
                     'rest_length': 0.28},
                    {'name': 's1', 'from': 'world.w1', 'to': 'bar.b', 'stiffness': 100.0,
                     'rest_length': 0.28}]}}
    a = analyse(Structure.from_dict(doc))
    assert (a.self_stresses, a.mechanisms, a.rigid_motions) == (0, 3, 0)
    assert a.framework.fixed.tolist() == [False, False, True, True]
    assert a.super_stable is None and a.strings_pull and a.prestress_stable
    t = 100.0 * (0.3 - 0.28)
    np.testing.assert_allclose(a.prestress_stiffness.min(), t / 0.3, rtol=1e-12)


@pytest.mark.parametrize('p', PRISMS)
def test_product_forces_of_the_prism_mechanisms_are_not_balanced(p):
    """Pellegrino & Calladine's test: the product forces of the self-stress and each mechanism
    lie outside the column space of A (no member forces balance them), so every mechanism is
    first-order stiffened; their components along the mechanisms are the prestress stiffness."""
    a = analyse(prism_structure(p))
    P = product_forces(a)
    fw = a.framework
    A = equilibrium_matrix(fw.positions, fw.members)[free_coordinates(fw.fixed)]
    balanced = A @ np.linalg.lstsq(A, P, rcond=None)[0]
    outside = np.linalg.norm(P - balanced, axis=0)
    assert np.all(outside > 1e-3 * np.linalg.norm(P, axis=0))
    Q = a.mechanism_basis.T @ P
    np.testing.assert_allclose(np.linalg.eigvalsh(0.5 * (Q + Q.T)), a.prestress_stiffness,
                               rtol=1e-10, atol=1e-12)


def test_a_flat_braced_square_is_prestress_stable_but_not_super_stable_in_space():
    """A square of strings braced by two crossing bars (in one plane): one self-stress (sides
    t, diagonals -sqrt(2) t: the bars push), the stress matrix PSD with nullity d + 1 = 3 of
    a planar framework, not the 4 that super stability asks in 3D; its one mechanism out of
    the plane (z alternating around the square) is stiffened by the prestress."""
    X = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    members = [(0, 1), (1, 2), (2, 3), (3, 0), (0, 2), (1, 3)]
    fw = Framework.build(('a', 'b', 'c', 'd'), X, members,
                         ('s0', 's1', 's2', 's3', 'bar0', 'bar1'), [False] * 4 + [True] * 2)
    a0 = analyse_framework(fw)
    assert (a0.self_stresses, a0.mechanisms, a0.rigid_motions) == (1, 1, 6)
    t = a0.self_stress_basis[:, 0]
    t = t / t[0]
    np.testing.assert_allclose(t, [1, 1, 1, 1, -math.sqrt(2), -math.sqrt(2)], rtol=1e-12)
    a = analyse_framework(fw.with_forces(t))
    assert a.strings_pull and a.stress_psd and a.stress_nullity == 3
    assert a.prestress_stable and not a.super_stable
    z = a.mechanism_basis[2::3, 0]  # out of the plane, alternating
    np.testing.assert_allclose(np.abs(z), 0.5, rtol=1e-12)
    assert z[0] * z[1] < 0 and z[0] * z[2] > 0


def test_the_cuiksuite_prism_has_its_published_spring_ratio():
    """Logan-Shi/CuikSuite, examples/Tensegrity/Formfinding/definePrism.m: a 3-prism's node
    coordinates (15 digits) and, as its strings are zero-rest-length springs (t = k l, so k is
    the force density), stiffnesses 0.175494628703572 (polygons) and 0.303965613370022
    (verticals). At those nodes our one self-stress has that ratio (sqrt 3) and the bars -sqrt 3.
    """
    X = np.array([[0.0, 0.0, 0.0], [0.965925826289067, 0.258819045102519, 1.064882435607910],
                  [0.896575472168053, 0.0, 0.0],
                  [0.189468690981504, 0.707106781186546, 1.064882435607910],
                  [0.448287736084027, 0.776457135307562, 0.0],
                  [0.189468690981504, -0.189468690981508, 1.064882435607910]])
    strings = [(1, 3), (3, 5), (1, 5), (2, 4), (4, 6), (2, 6), (1, 6), (2, 3), (4, 5)]
    bars = [(1, 2), (3, 4), (5, 6)]
    members = [(i - 1, j - 1) for i, j in strings + bars]
    fw = Framework.build(tuple(f'n{k}' for k in range(1, 7)), X, members,
                         tuple(f'm{k}' for k in range(12)), [False] * 9 + [True] * 3)
    a = analyse_framework(fw)
    assert (a.self_stresses, a.mechanisms) == (1, 1)
    q = a.self_stress_basis[:, 0] / fw.lengths
    q /= q[0]
    ratio = 0.303965613370022 / 0.175494628703572
    np.testing.assert_allclose(q[:6], 1.0, rtol=1e-9)
    np.testing.assert_allclose(q[6:9], ratio, rtol=1e-9)
    np.testing.assert_allclose(q[9:], -ratio, rtol=1e-9)
    assert ratio == pytest.approx(math.sqrt(3.0), rel=1e-13)
