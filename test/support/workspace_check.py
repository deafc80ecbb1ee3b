"""Run inside a colcon workspace after ``source install/setup.bash`` (by test_workspace_build):
the installed ``stiffness_node`` answers with the library's K and an equilibrium, and the C++
consumer package's ``joint_stiffness`` (built against the target ``tensegrity_stiffness::kernel``)
computes the default joint's F, K and K_c as the Python library does.

Usage: ``python workspace_check.py WS_INSTALL_DIR``. Everything is taken from the workspace's
install space, found as ``ros2 run`` finds it (the ament index): the executables, the config, the
Python package, the generated service type and the compiled kernel. Prints ``WORKSPACE OK`` and
exits 0, or raises.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

# Run as a script: the test folder, which holds the support package, on the path.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


#: The consumer package of test_workspace_build and its C++ program.
CONSUMER, CONSUMER_PROGRAM = 'tensegrity_consumer', 'joint_stiffness'


def check_cpp_consumer(install: Path, config: Path) -> float:
    """The consumer's C++ program on the default joint at its initial_screw against the Python
    library (the compiled path and the numpy reference): K and K_c to 1e-12 of their largest
    entry, F of the largest tension. Returns the largest relative difference."""
    from ament_index_python.packages import get_package_prefix

    from tensegrity_stiffness.mechanics.joint import FORCE_LAWS, JointModel

    program = Path(get_package_prefix(CONSUMER)) / 'lib' / CONSUMER / CONSUMER_PROGRAM
    assert install in program.parents and program.is_file(), f'{program} not installed'
    model = JointModel.from_yaml(config)
    reference = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                           link2_nodes=model.link2_nodes, max_lengths=model.max_lengths,
                           force_law=model.force_law, initial_screw=model.initial_screw,
                           use_kernel=False)
    assert model.uses_kernel and not reference.uses_kernel
    arrays = {'p1': model.link1_string_nodes, 'p2': model.link2_nodes[model.connections[:, 1]],
              'k': model.k, 'max_stretch': model.max_stretch, 'rest': model.rest_lengths,
              'xi': model.initial_screw, 'law': [FORCE_LAWS.index(model.force_law)]}
    text = ''.join(f'{name} ' + ' '.join(repr(float(v)) for v in np.ravel(values)) + '\n'
                   for name, values in arrays.items())
    input_file = install.parent / 'joint_stiffness_input.txt'
    input_file.write_text(text)
    ran = subprocess.run([str(program), str(input_file)], capture_output=True, text=True,
                         timeout=60)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    got = {line.split()[0]: np.array([float(v) for v in line.split()[1:]])
           for line in ran.stdout.splitlines() if line.strip()}
    worst = 0.0
    for python in (model, reference):
        state = python.evaluate(python.initial_screw)
        for name, want in (('F', state.wrench), ('K', state.stiffness),
                           ('K_c', state.cartesian_stiffness)):
            want = np.ravel(want)
            # F is zero at this equilibrium to 1e-13: measured against the largest tension.
            scale = np.max(np.abs(want)) if name != 'F' else np.max(state.tensions)
            error = float(np.max(np.abs(got[name] - want)) / scale)
            assert error < 1e-12, f'C++ {name} differs from the library by {error:.2e}'
            worst = max(worst, error)
    if shutil.which('ldd'):
        linked = subprocess.run(['ldd', str(program)], capture_output=True, text=True).stdout
        assert str(install / 'tensegrity_stiffness' / 'lib') in linked, linked
    return worst


def main(install: Path) -> None:
    from ament_index_python.packages import get_package_prefix, get_package_share_directory
    from std_msgs.msg import Float64MultiArray
    from tensegrity_stiffness.srv import SolveEquilibrium

    import tensegrity_stiffness
    from support.ros_harness import NodeProcess, RosClient, unique_namespace
    from tensegrity_stiffness.mechanics import kernel
    from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
    from tensegrity_stiffness.mechanics.joint import JointModel

    prefix = Path(get_package_prefix('tensegrity_stiffness'))
    assert prefix == install / 'tensegrity_stiffness', f'ament index finds {prefix}'
    package_dir = Path(os.path.abspath(tensegrity_stiffness.srv.__file__)).parents[1]
    assert install in package_dir.parents, f'tensegrity_stiffness.srv from {package_dir}'
    assert str(install) in kernel.status(), f'kernel: {kernel.status()}'
    config = Path(get_package_share_directory('tensegrity_stiffness')) / 'config' / \
        'default_joint.yaml'
    launch_dir = config.parents[1] / 'launch'
    assert (launch_dir / 'stiffness_node.launch.py').is_file(), 'launch files not installed'

    cpp_error = check_cpp_consumer(install, config)
    print(f'C++ consumer: F, K, K_c relative error {cpp_error:.1e}')

    reference = JointModel.from_yaml(config)
    xi = np.array([0.05, -2.9, 0.3, 0.004, -0.01, 0.12])
    ns = unique_namespace('ws')
    proc = NodeProcess(ns, config)
    ros = RosClient('workspace_check')
    try:
        base = f'{ns}/stiffness_node'
        stiffness = ros.subscribe(Float64MultiArray, f'{base}/stiffness')
        screw = ros.publisher(Float64MultiArray, f'{base}/screw')
        solve = ros.client(SolveEquilibrium, f'{base}/solve_equilibrium')
        ros.wait_for_subscribers(screw)
        ros.wait_for_publishers(f'{base}/stiffness')
        screw.publish(Float64MultiArray(data=xi.tolist()))
        K = np.asarray(stiffness.wait_for(1, timeout=10.0)[0].data).reshape(6, 6)
        expected = reference.stiffness(xi)
        error = np.max(np.abs(K - expected)) / np.max(np.abs(expected))
        assert error < 1e-12, f'K differs from the library by {error:.2e}'

        response = ros.call(solve, SolveEquilibrium.Request(), timeout=30.0)
        assert response.success, response.message
        library = solve_equilibrium(reference, np.zeros(6))
        gap = np.max(np.abs(np.asarray(response.screw) - library.screw))
        assert gap < 1e-8, f'equilibrium screw differs from the library by {gap:.2e}'
        assert response.residual < 1e-8, response.residual
        deadline = time.monotonic() + 5.0
        while 'compiled kernel' not in proc.log() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert 'compiled kernel' in proc.log(), proc.log()
    finally:
        ros.close()
        code = proc.stop()
    assert code == 0, f'node exit code {code}:\n{proc.log()}'
    print(f'K relative error {error:.1e}, equilibrium gap {gap:.1e} m, '
          f'residual {response.residual:.1e}')

    # The other executables start from the install space as `ros2 run` starts them.
    spine = NodeProcess(unique_namespace('ws'), config.with_name('default_spine.yaml'),
                        executable='spine_node')
    try:
        deadline = time.monotonic() + 30.0
        while 'ready:' not in spine.log() and time.monotonic() < deadline:
            assert spine.alive(), spine.log()
            time.sleep(0.05)
        assert 'ready:' in spine.log() and 'compiled kernel' in spine.log(), spine.log()
        time.sleep(0.5)  # spinning (a stop within milliseconds of start-up is not clean yet)
    finally:
        code = spine.stop()
    assert code == 0, f'spine_node exit code {code}:\n{spine.log()}'
    for command in (prefix / 'lib' / 'tensegrity_stiffness' / 'tensegrity-stiffness',
                    Path(shutil.which('tensegrity-stiffness') or 'missing')):
        assert install in command.parents, f'{command} is not from the workspace'
        ran = subprocess.run([str(command), 'joint', '--help'], capture_output=True,
                             text=True, timeout=60)
        assert ran.returncode == 0, ran.stdout + ran.stderr
    print('WORKSPACE OK')


if __name__ == '__main__':
    main(Path(sys.argv[1]).resolve())
