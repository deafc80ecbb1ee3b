"""Names of the components of the package's 6-vectors, in their order: one home for the nodes'
labels, the command line, the interpretation of K and the design reports.

Wrenches ``[f; m]`` (rows of K and K_c), screws ``xi = [omega; v]`` (columns of K, Monke & Vikas
eqs. 1-5) and spatial twists in {1} linear first, as ROS orders 6-vectors (columns of K_c).
"""

WRENCH_NAMES = ('fx', 'fy', 'fz', 'mx', 'my', 'mz')
SCREW_NAMES = ('wx', 'wy', 'wz', 'vx', 'vy', 'vz')
TWIST_NAMES = ('dx', 'dy', 'dz', 'rx', 'ry', 'rz')
#: Names of the four 3x3 blocks of K (Monke & Vikas eq. 19), in the order of the interpretation.
BLOCK_NAMES = ('K_fw', 'K_fv', 'K_mw', 'K_mv')
