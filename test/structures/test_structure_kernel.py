"""The structures' compiled kernel (src/structure_kernel.cpp) equals the numpy reference to
1e-12 (every output, the regions exactly), refuses bad arguments, and reads only arrays that
live until it returns (the poisoned-call proof of test/kernel/test_kernel_boundary.py, and
AddressSanitizer on the kernel compiled with it: slow)."""

import textwrap

import numpy as np
import pytest
from structure_fixtures import PRISM3, SIXBAR, example, mixed_document, perturbed
from support.kernel_checks import assert_asan_clean, poisoned

from tensegrity_stiffness.mechanics import kernel as joint_kernel
from tensegrity_stiffness.structures import kernel
from tensegrity_stiffness.structures.structure import Structure

pytestmark = pytest.mark.skipif(not kernel.available(), reason=kernel.status())

RTOL = 1e-12
FIELDS = ('string_vectors', 'lengths', 'tensions', 'stiffness', 'bar_forces', 'node_forces')


def pairs():
    for name in (PRISM3, SIXBAR):
        yield name, example(name), example(name, use_kernel=False)
    for law in ('hooke', 'paper'):
        document = mixed_document(law)
        yield law, Structure.from_dict(document), Structure.from_dict(document, use_kernel=False)


def assert_same(state, ref, name):
    np.testing.assert_array_equal(state.slack, ref.slack, err_msg=name)
    np.testing.assert_array_equal(state.saturated, ref.saturated, err_msg=name)
    for field in FIELDS:
        new, old = getattr(state, field), getattr(ref, field)
        assert new.shape == old.shape, (name, field)
        scale = max(np.max(np.abs(old), initial=0.0), 1e-300)
        np.testing.assert_allclose(new, old, rtol=0, atol=RTOL * scale, err_msg=f'{name} {field}')
    scale = np.sum(np.abs(ref.tensions)) * (1.0 + max(np.max(np.abs(ref.poses[:, :3, 3])), 1.0))
    assert np.max(np.abs(state.wrenches - ref.wrenches)) <= RTOL * scale, name


@pytest.mark.parametrize('seed', range(4))
def test_the_kernel_equals_numpy(seed):
    rng = np.random.default_rng(seed)
    for name, compiled, reference in pairs():
        assert compiled.uses_kernel and not reference.uses_kernel
        T = perturbed(compiled.start_poses(), rng, 0.05)
        rest = compiled.rest_lengths * rng.uniform(0.8, 1.1, compiled.n_strings)
        assert_same(compiled.evaluate(T, rest), reference.evaluate(T, rest), name)
        wrench = compiled.evaluate_transforms(T, rest, wrench_only=True)
        assert np.all(np.isnan(wrench.stiffness))
        np.testing.assert_array_equal(wrench.wrenches, compiled.evaluate(T, rest).wrenches)


def test_a_zero_length_string_is_named_on_both_paths():
    document = mixed_document()
    structure = Structure.from_dict(document)
    T = structure.start_poses()
    # Put bar0's node a onto hub.A: string hub.A-bar0.a has zero length.
    hub_a = T[0, :3, :3] @ structure.body('hub').nodes['A'] + T[0, :3, 3]
    T[1, :3, 3] += hub_a - (T[1, :3, :3] @ structure.body('bar0').nodes['a'] + T[1, :3, 3])
    with pytest.raises(ValueError, match=r"strings \['hub.A-bar0.a'\] have zero length"):
        structure.evaluate(T)


def _raw_call(structure, **change):
    kn = structure.compiled_kernel
    args = dict(n_bodies=kn.n_bodies, n_strings=kn.n, ends=kn.ends, points=kn.points, k=kn.k,
                rest=np.ascontiguousarray(structure.rest_lengths), stretch=kn.max_stretch,
                law=kn.law, T=np.ascontiguousarray(structure.start_poses()), mode=0,
                out=np.empty(kn.size))
    args.update(change)
    address = joint_kernel.address
    return kn.call(args['n_bodies'], args['n_strings'], address(args['ends']),
                   address(args['points']), address(args['k']), address(args['rest']),
                   address(args['stretch']), args['law'], 1e-12, address(args['T']),
                   args['mode'], address(args['out']), args['out'].size)


def test_the_kernel_refuses_bad_counts_arguments_and_short_buffers():
    structure = example(SIXBAR)
    assert _raw_call(structure) == joint_kernel.OK
    assert _raw_call(structure, n_bodies=0) == -2
    assert _raw_call(structure, mode=1) == -4
    assert _raw_call(structure, law=2) == -4
    assert _raw_call(structure, out=np.empty(10)) == -3
    bad = structure.string_bodies.astype(np.int64).copy()
    bad[0, 0] = 6
    assert _raw_call(structure, ends=bad) == -4


def test_only_live_arrays_reach_the_kernel(monkeypatch):
    """Every freed block below 1 KiB is handed out again and NaN-filled between Python's
    argument evaluation and the C call: the kernel's results must not change (strided rest
    lengths and poses are the inputs that the loader copies)."""
    rng = np.random.default_rng(9)
    structure = example(SIXBAR)
    reference = example(SIXBAR, use_kernel=False)
    kn = structure.compiled_kernel
    call = kn.call

    monkeypatch.setattr(kn, 'call', poisoned(call))
    T = perturbed(structure.start_poses(), rng, 0.05)
    strided_T = np.empty((6, 4, 4, 2))
    strided_T[..., 0] = T
    rest = np.empty((structure.n_strings, 2))
    rest[:, 0] = structure.rest_lengths * 0.95
    state = structure.evaluate_transforms(strided_T[..., 0], rest[:, 0])
    assert_same(state, reference.evaluate_transforms(T, rest[:, 0].copy()), 'poisoned')


ASAN_SCRIPT = textwrap.dedent('''
    import numpy as np
    from tensegrity_stiffness.structures.elements import Body, StringSpec
    from tensegrity_stiffness.structures.structure import Structure
    rng = np.random.default_rng(44)
    # 24 bodies (poses of 3 KB) and 240 strings (rest lengths of 1.9 KB): numpy frees such
    # buffers to malloc, where AddressSanitizer sees a read after the free.
    bodies = [Body.rigid(f'b{i}', {'p': rng.normal(size=3) * 0.05,
                                   'q': rng.normal(size=3) * 0.05},
                         pose=[*rng.normal(size=3), 0.0, 0.0, 0.0, 1.0]) for i in range(24)]
    strings = [StringSpec(f's{j}', f'b{j % 24}.p', f'b{(j * 7 + 1) % 24}.q', 50.0, 0.2)
               for j in range(240)]
    structure = Structure(bodies, strings)
    assert structure.uses_kernel
    T = structure.start_poses()
    strided_T = np.repeat(T[..., None], 2, axis=-1)[..., 1]
    rests = np.full((240, 2), 0.2)
    state = structure.evaluate_transforms(strided_T, rests[:, 1])
    assert np.isfinite(state.stiffness).all()
    print('ok')
''')


@pytest.mark.slow
def test_addresssanitizer_finds_no_use_after_free_in_the_structure_kernel(tmp_path):
    assert_asan_clean(tmp_path, ASAN_SCRIPT)
