"""``tensegrity-stiffness``: inspect a joint and draw the papers' figures from the command line.

Runs on the library alone (numpy, scipy, PyYAML; matplotlib for plots) -- no node, no rclpy.
Subcommands (``tensegrity-stiffness <command> --help`` for every option):

* ``joint``        wrench, K, K_c, tensions, interpretation at a screw or pose (eqs. 6-11, 19-20)
* ``equilibrium``  the equilibrium under an external wrench (Section VI)
* ``planar-fk``    planar mechanism forward kinematics at (L3, theta1) (eqs. 2-7, 17-30, 42)
* ``planar-ik``    planar mechanism inverse kinematics at D3 = (x, y) (eqs. 8-16, 48-52)
* ``design``       rest lengths that hold a screw under a load within tension limits, with a
  chosen Cartesian stiffness (:mod:`tensegrity_stiffness.mechanics.design`)
* ``plot <figure>`` one PNG: ``joint``, ``extension`` (Monke & Vikas Figs. 4-5),
  ``actuator-workspace``, ``cartesian-workspace`` (Ji, Li & Lin Figs. 2-3), ``theta2``
  (Figs. 4-6), ``actuator-stiffness``, ``cartesian-stiffness`` (Figs. 7-8), ``stiffness-range``
  (reachable diagonal of K_c along a screw sweep)
* ``chain``        a spine of joints: tip pose and exact tip stiffness at screws, or at the chain
  equilibrium under a tip wrench and link weights (``plot spine`` draws it)
* ``figures``      every figure of docs/figures.md into a folder (``docs/figures``)
* ``bag``          what the node would publish, for a whole rosbag2 recording (needs rosbags)
* ``calibrate``    each string's stiffness and rest-length offset from a recording (rosbag2 or
  CSV), with identifiability and std (:mod:`tensegrity_stiffness.cli.calibration_report`)

Numbers accept arithmetic with ``pi`` (``pi/10``, ``-3*pi/4``, ``-1e-3``). ``--json`` prints
machine-readable output (NaN and inf as null). Exit codes: 0 success, 1 no solution (equilibrium
not found, unreachable point), 2 bad input (message on stderr, no traceback), 3 matplotlib
missing. Progress of long computations goes to stderr, only when stderr is a terminal.
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import operator
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.cli import plots
from tensegrity_stiffness.geometry.components import TWIST_NAMES
from tensegrity_stiffness.geometry.quaternion import quaternion_to_rotation, rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import CHART_LIMIT, log_se3
from tensegrity_stiffness.mechanics import design, sweeps
from tensegrity_stiffness.mechanics.chain import (
    DEFAULT_SPINE_CONFIG,
    JointChain,
    solve_chain_equilibrium,
)
from tensegrity_stiffness.mechanics.equilibrium import is_stable, solve_equilibrium
from tensegrity_stiffness.mechanics.interpretation import (
    BLOCK_NAMES,
    COLUMN_NAMES,
    ROW_NAMES,
    interpret_stiffness,
)
from tensegrity_stiffness.mechanics.joint import FORCE_LAWS, JointModel, JointState
from tensegrity_stiffness.mechanics.planar import SINGULARITY_DESCRIPTIONS, PlanarMechanism
from tensegrity_stiffness.nodes import parameters

FloatArray = NDArray[np.float64]

PROG = 'tensegrity-stiffness'
EXIT_OK = 0
EXIT_NO_SOLUTION = 1
EXIT_BAD_INPUT = 2
EXIT_NO_MATPLOTLIB = 3

#: Table cells: width (characters) and relative size below which an entry is shown as 0.
CELL_WIDTH = 13
DISPLAY_ZERO = 1e-12
#: Longest accepted numeric expression (characters).
MAX_EXPRESSION_LENGTH = 100
#: Column labels of K_c: a spatial twist in {1}, linear first (the node's labels).
KC_COLUMN_NAMES = TWIST_NAMES
#: Keys of the planar mechanism (the node's ``planar.*`` parameters without the prefix).
PLANAR_KEYS = tuple(spec.name[len('planar.'):] for spec in parameters.PLANAR_PARAMETERS)
#: Screw of the joint figure (docs/figures.md): the default joint's unloaded equilibrium bent by
#: 0.4 rad about the x axis of {1} (two strings go slack).
README_JOINT_SCREW = (2.3963, 0.4857, -2.3963, 0.0198, -0.0033, 0.0161)
#: PNG file of each figure (``plot`` default output name and ``figures`` file name).
FIGURE_FILES = {
    'joint': 'joint_3d.png',
    'extension': 'extension_sweep.png',
    'actuator-workspace': 'planar_actuator_workspace.png',
    'cartesian-workspace': 'planar_cartesian_workspace.png',
    'theta2': 'planar_theta2.png',
    'actuator-stiffness': 'planar_stiffness_actuator.png',
    'cartesian-stiffness': 'planar_stiffness_cartesian.png',
    'stiffness-range': 'stiffness_range.png',
    'spine': 'spine.png',
}
#: Accepted range of ``figures --scale``.
SCALE_RANGE = (0.1, 4.0)


# ------------------------------------------------------------------------------ input parsing
_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
           ast.Div: operator.truediv, ast.Pow: operator.pow}
_UNARY = {ast.UAdd: operator.pos, ast.USub: operator.neg}


def _evaluate(node: ast.AST) -> float:
    """Value of a parsed arithmetic expression of numbers and ``pi`` (nothing else)."""
    if isinstance(node, ast.Expression):
        return _evaluate(node.body)
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return float(node.value)
    if isinstance(node, ast.Name) and node.id == 'pi':
        return math.pi
    if isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
        return _UNARY[type(node.op)](_evaluate(node.operand))
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        return float(_BINARY[type(node.op)](_evaluate(node.left), _evaluate(node.right)))
    raise ValueError('not an arithmetic expression')


def parse_number(text: str) -> float:
    """A finite float from ``text``: a number or arithmetic with ``pi`` (e.g. ``-3*pi/4``)."""
    s = str(text).strip()
    try:
        if len(s) > MAX_EXPRESSION_LENGTH:
            raise ValueError('too long')
        value = _evaluate(ast.parse(s, mode='eval'))
    except (SyntaxError, ValueError, TypeError, ZeroDivisionError, OverflowError,
            RecursionError):
        raise argparse.ArgumentTypeError(
            f'not a number: {s!r} (examples: 0.5, -1e-3, pi/10)') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'not a finite number: {s!r}')
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(str(text).strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be >= 1, got {value}')
    return value


def _is_number(token: str) -> bool:
    try:
        parse_number(token)
    except argparse.ArgumentTypeError:
        return False
    return True


def _protect_negative_numbers(argv: Sequence[str]) -> list[str]:
    """argparse takes ``-1e-3`` or ``-pi/2`` for an option: prefix such numbers with a space
    (stripped again by :func:`parse_number`) so that they are read as values."""
    out = []
    for token in argv:
        if len(token) > 1 and token[0] == '-' and token[1] != '-' and _is_number(token):
            token = ' ' + token
        out.append(token)
    return out


# ------------------------------------------------------------------------------ progress
class TerminalProgress:
    """``label: 42% (n/total)`` rewritten in place on ``stream`` (stderr by default), only when
    the stream is a terminal; a newline when done. Use as ``progress(done, total)``."""

    def __init__(self, label: str, stream: TextIO | None = None) -> None:
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, 'isatty', None)
        self.enabled = bool(isatty()) if callable(isatty) else False
        self._last = -1

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        percent = 100 if total <= 0 else int(100 * min(done, total) / total)
        if percent == self._last:
            return
        self._last = percent
        self.stream.write(f'\r{self.label}: {percent:3d}% ({done}/{total})')
        if done >= total:
            self.stream.write('\n')
        self.stream.flush()

    def finish(self) -> None:
        """End a started line that did not reach 100% (nothing if nothing was written)."""
        if self.enabled and 0 <= self._last < 100:
            self.stream.write('\n')
            self.stream.flush()
            self._last = 100


class TerminalRateProgress(TerminalProgress):
    """:class:`TerminalProgress` with the rate and the time left:
    ``label: 42% (n/total) 23456/s ETA 3 s``."""

    def __init__(self, label: str, unit: str = '/s', stream: TextIO | None = None) -> None:
        super().__init__(label, stream)
        self.unit = unit
        self._start = time.perf_counter()

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        elapsed = max(time.perf_counter() - self._start, 1e-9)
        rate = done / elapsed
        percent = 100 if total <= 0 else int(100 * min(done, total) / total)
        eta = f'ETA {(total - done) / rate:.0f} s' if 0 < rate and done < total else \
            f'in {elapsed:.1f} s'
        self.stream.write(f'\r{self.label}: {percent:3d}% ({done}/{total}) '
                          f'{rate:.0f}{self.unit} {eta}   ')
        self._last = percent
        if done >= total:
            self.stream.write('\n')
        self.stream.flush()


# ------------------------------------------------------------------------------ formatting
def _num(value: float, width: int = 0) -> str:
    text = 'nan' if value is None or not math.isfinite(value) else f'{value:.6g}'
    if text == '-0':
        text = '0'
    return text.rjust(width)


def _vector(values: Sequence[float] | FloatArray) -> str:
    return '[' + ' '.join(_num(float(v)) for v in values) + ']'


def _display(values: FloatArray) -> FloatArray:
    """``values`` with entries below :data:`DISPLAY_ZERO` times the largest shown as 0 (tables
    only; JSON carries the exact values)."""
    values = np.asarray(values, dtype=np.float64)
    finite = values[np.isfinite(values)]
    scale = float(np.abs(finite).max()) if finite.size else 0.0
    return np.where(np.abs(values) < DISPLAY_ZERO * scale, 0.0, values)


def _matrix_lines(M: FloatArray, rows: Sequence[str], cols: Sequence[str],
                  width: int = CELL_WIDTH) -> list[str]:
    lines = ['      ' + ''.join(c.rjust(width) for c in cols)]
    for name, row in zip(rows, _display(M), strict=True):
        lines.append(f'  {name:<4}' + ''.join(_num(float(v), width) for v in row))
    return lines


def _jsonable(obj: Any) -> Any:
    """numpy -> plain Python; NaN and inf -> None (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def _print_json(obj: Any) -> None:
    print(json.dumps(_jsonable(obj), indent=2, allow_nan=False))


def _yes(flag: bool) -> str:
    return 'yes' if flag else 'no'


# ------------------------------------------------------------------------------ joint inputs
def _load_joint(args: argparse.Namespace) -> tuple[JointModel, Path, FloatArray]:
    """Joint model, config path and rest lengths (n,) from --config, --force-law,
    --rest-lengths."""
    path = Path(args.config) if args.config else config.packaged_config_path()
    try:
        section = dict(config.load_section(path, 'joint'))
    except ValueError as exc:
        raise ValueError(f'config {path}: {exc}') from None
    if args.force_law:
        section['force_law'] = args.force_law
    model = JointModel.from_dict(section)
    rest = model.rest_lengths
    if args.rest_lengths:
        values = np.asarray(args.rest_lengths, dtype=np.float64)
        if values.size == 1:
            values = np.full(model.n_strings, values[0])
        if values.size != model.n_strings:
            raise ValueError(f'--rest-lengths needs 1 or {model.n_strings} values (one per '
                             f'string), got {values.size}')
        rest = model.validate_rest_lengths(values, batched=False)
    return model, path, rest


def _screw(args: argparse.Namespace, model: JointModel) -> FloatArray:
    """The screw of --screw, or of --pose (on the branch nearest the config's initial screw, as
    the node does), or the config's initial screw (the unloaded equilibrium)."""
    if args.screw is not None:
        xi = np.asarray(args.screw, dtype=np.float64)
        if np.linalg.norm(xi[:3]) >= CHART_LIMIT:
            raise ValueError('--screw must have |omega| = |(wx, wy, wz)| < 2 pi')
        return xi
    if args.pose is not None:
        T = np.eye(4)
        try:  # the node's rule: unit within QUATERNION_UNIT_TOLERANCE, renormalised
            T[:3, :3] = quaternion_to_rotation(args.pose[3:])
        except ValueError as exc:
            raise ValueError(f'--pose [x y z qx qy qz qw]: {exc}') from None
        T[:3, 3] = args.pose[:3]
        return log_se3(T, reference=model.initial_screw)
    return model.initial_screw.copy()


def joint_report(model: JointModel, state: JointState, rest: FloatArray,
                 config: Path | str) -> dict[str, Any]:
    """Everything ``joint`` prints, as a JSON-ready dict (orderings as in docs/conventions.md)."""
    interp = interpret_stiffness(state.stiffness)
    T = state.transform
    strings = [
        {'name': name, 'link1_node': model.node_names[a], 'link2_node': model.link2_node_names[b],
         'length': float(length), 'rest_length': float(l0), 'tension': float(t),
         'state': 'slack' if sl else ('saturated' if sat else 'taut')}
        for name, (a, b), length, l0, t, sl, sat in zip(
            model.string_names, model.connections, state.lengths, rest, state.tensions,
            state.slack, state.saturated, strict=True)]
    return {
        'config': str(config),
        'force_law': model.force_law,
        'screw': state.screw,
        'transform': T,
        'position': T[:3, 3],
        'quaternion': rotation_to_quaternion(T[:3, :3]),
        'wrench': state.wrench,
        'energy': float(model.energy(state.screw, rest)),
        'stiffness': state.stiffness,
        'cartesian_stiffness': state.cartesian_stiffness,
        'cartesian_stiffness_positive_definite': is_stable(state.cartesian_stiffness),
        'tensions': state.tensions,
        'strings': strings,
        'interpretation': {
            'block_norms': dict(zip(BLOCK_NAMES, interp.block_norms, strict=True)),
            'column_norms': dict(zip(COLUMN_NAMES, interp.column_norms, strict=True)),
            'row_norms': dict(zip(ROW_NAMES, interp.row_norms, strict=True)),
        },
    }


def _print_joint(report: dict[str, Any]) -> None:
    n = len(report['strings'])
    print(f"joint: {report['config']} ({n} strings, force law {report['force_law']})")
    print(f"screw xi [wx wy wz vx vy vz] (rad, m): {_vector(_display(report['screw']))}")
    print(f"pose of link 2 in {{1}}: position (m) {_vector(_display(report['position']))}, "
          f"quaternion [x y z w] {_vector(_display(report['quaternion']))}")
    print(f"elastic energy U: {_num(report['energy'])} J")
    print()
    print('string wrench F on link 2, in {1} about its origin (N, N m), eq. 9:')
    print('      ' + ''.join(c.rjust(CELL_WIDTH) for c in ROW_NAMES))
    print('      ' + ''.join(_num(float(v), CELL_WIDTH) for v in _display(report['wrench'])))
    print()
    print('strings (eq. 8):')
    print(f"  {'name':<14}{'nodes':>8}{'length (m)':>13}{'rest (m)':>11}{'tension (N)':>13}"
          '  state')
    for s in report['strings']:
        nodes = f"{s['link1_node']}-{s['link2_node']}"
        print(f"  {s['name']:<14}{nodes:>8}{_num(s['length'], 13)}{_num(s['rest_length'], 11)}"
              f"{_num(s['tension'], 13)}  {s['state']}")
    print()
    print('stiffness K = dF/dxi (eq. 10); rows: wrench (N, N m), columns: screw (rad, m):')
    print('\n'.join(_matrix_lines(np.asarray(report['stiffness']), ROW_NAMES, COLUMN_NAMES)))
    print()
    print('Cartesian stiffness K_c = -dF/d[dv; dw]; columns: spatial twist in {1}, linear first:')
    print('\n'.join(_matrix_lines(np.asarray(report['cartesian_stiffness']), ROW_NAMES,
                                  KC_COLUMN_NAMES)))
    print(f"  symmetric part positive definite: "
          f"{_yes(report['cartesian_stiffness_positive_definite'])}")
    print()
    interp = report['interpretation']
    print('interpretation (eqs. 19-20):')
    for title, key in (('block Frobenius norms', 'block_norms'),
                       ('column norms', 'column_norms'), ('row norms', 'row_norms')):
        cells = '  '.join(f'{k} {_num(v)}' for k, v in interp[key].items())
        print(f'  {title:<22} {cells}')


# ------------------------------------------------------------------------------ handlers
def _cmd_joint(args: argparse.Namespace) -> int:
    model, path, rest = _load_joint(args)
    state = model.evaluate(_screw(args, model), rest)
    report = joint_report(model, state, rest, path)
    if args.json:
        _print_json(report)
    else:
        _print_joint(report)
    return EXIT_OK


def _cmd_equilibrium(args: argparse.Namespace) -> int:
    model, path, rest = _load_joint(args)
    x0 = None if args.initial_screw is None else np.asarray(args.initial_screw)
    result = solve_equilibrium(model, np.asarray(args.wrench), rest, x0,
                               time_budget=args.time_budget)
    report: dict[str, Any] = {
        'external_wrench': np.asarray(args.wrench), 'success': result.success,
        'message': result.message, 'residual': result.residual,
        'iterations': result.iterations, 'stable': result.stable, 'screw': result.screw}
    if result.state is not None:
        report['joint'] = joint_report(model, result.state, rest, path)
    if args.json:
        _print_json(report)
    else:
        print(f"equilibrium under W = {_vector(report['external_wrench'])} (N, N m): "
              f'{result.message}')
        print(f'  residual |F + W| = {_num(result.residual)}, iterations {result.iterations}, '
              f'stable: {_yes(result.stable)}')
        print()
        if result.state is not None:
            _print_joint(report['joint'])
    if not result.success:
        print(f'{PROG}: no equilibrium found: {result.message}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    return EXIT_OK


def _planar(args: argparse.Namespace, base: dict[str, float]) -> PlanarMechanism:
    """PlanarMechanism from ``base`` overridden by the --L, --K1, ... options that were given."""
    params = dict(base)
    for key in PLANAR_KEYS:
        value = getattr(args, f'planar_{key}', None)
        if value is not None:
            params[key] = value
    return PlanarMechanism(**{k: params[k] for k in PLANAR_KEYS if k in params})


def _planar_config(args: argparse.Namespace) -> dict[str, float]:
    """The node's planar parameters: the ``planar`` section of --config (default: the packaged
    config), missing keys from the node's parameter table."""
    path = Path(args.config) if args.config else config.packaged_config_path()
    section = config.load_section(path, 'planar', required=False)
    params = {}
    for spec in parameters.PLANAR_PARAMETERS:
        key = spec.name[len('planar.'):]
        try:
            params[key] = spec.check(section.get(key, spec.default))
        except ValueError as exc:
            raise ValueError(f'config {path}: {exc}') from None
    return params


def _mech_line(mech: PlanarMechanism) -> str:
    return (f'L = {_num(mech.L)} m, K1 = {_num(mech.K1)} N/m, K2 = {_num(mech.K2)} N/m, '
            f'L3 in [{_num(mech.L3_min)}, {_num(mech.L3_max)}] m, theta1 in '
            f'[{_num(mech.theta1_min)}, {_num(mech.theta1_max)}], theta2 in '
            f'[{_num(mech.theta2_min)}, {_num(mech.theta2_max)}] rad')


def _singularity_lines(names: Sequence[str]) -> list[str]:
    if not names:
        return ['  singular conditions: none']
    return ['  singular conditions:'] + [f'    {n}: {SINGULARITY_DESCRIPTIONS[n]}'
                                         for n in names]


def _cmd_planar_fk(args: argparse.Namespace) -> int:
    mech = _planar(args, _planar_config(args))
    r = mech.forward(args.L3, args.theta1)
    report = {name: getattr(r, name) for name in r.__dataclass_fields__}
    report['mechanism'] = {k: getattr(mech, k) for k in PLANAR_KEYS}
    if args.json:
        _print_json(report)
        return EXIT_OK
    print(f'planar forward kinematics ({_mech_line(mech)})')
    print(f'  actuator        L3 = {_num(r.L3)} m, theta1 = {_num(r.theta1)} rad '
          f'(in range: {_yes(r.actuator_in_range)})')
    print(f'  D3              x = {_num(r.x)} m, y = {_num(r.y)} m')
    print(f'  theta2          {_num(r.theta2)} rad (stable root of eq. 5; in range: '
          f'{_yes(r.theta2_in_range)})')
    print(f'  stiffness K     {_num(r.stiffness)} N m/rad (eq. 42)')
    print(f'  energy U        {_num(r.energy)} J (eq. 4)')
    print(f'  stable          {_yes(r.stable)}')
    print(f'  unstable root   theta2 = {_num(r.theta2_unstable)} rad, D3 = ({_num(r.x_unstable)}'
          f', {_num(r.y_unstable)}) m, K = {_num(r.stiffness_unstable)} N m/rad')
    print(f'  Jacobian d(x, y)/d(L3, theta1) (eqs. 17-22): {_vector(r.jacobian[0])} '
          f'{_vector(r.jacobian[1])}, det J = {_num(r.jacobian_determinant)} m')
    print('\n'.join(_singularity_lines(r.singularities)))
    return EXIT_OK


def _cmd_planar_ik(args: argparse.Namespace) -> int:
    mech = _planar(args, _planar_config(args))
    result = mech.inverse(args.x, args.y, include_unstable=args.include_unstable,
                          require_theta2_in_range=args.require_theta2_in_range)
    solutions = [{name: getattr(s, name) for name in s.__dataclass_fields__} for s in result]
    report = {'x': result.x, 'y': result.y, 'solutions': solutions, 'reason': result.reason,
              'mechanism': {k: getattr(mech, k) for k in PLANAR_KEYS}}
    if args.json:
        _print_json(report)
    else:
        print(f'planar inverse kinematics of D3 = ({_num(result.x)}, {_num(result.y)}) m '
              f'({_mech_line(mech)})')
        if not solutions:
            print(f'  no solution: {result.reason}')
        else:
            print(f"  {'#':<3}{'L3 (m)':>11}{'theta1':>11}{'theta2':>11}{'K (N m/rad)':>13}"
                  f"{'U (J)':>11}{'det J (m)':>11}  stable  theta2 in range  singular")
            for k, s in enumerate(result):
                print(f'  {k:<3}{_num(s.L3, 11)}{_num(s.theta1, 11)}{_num(s.theta2, 11)}'
                      f'{_num(s.stiffness, 13)}{_num(s.energy, 11)}'
                      f'{_num(s.jacobian_determinant, 11)}  {_yes(s.stable):<6}  '
                      f'{_yes(s.theta2_in_range):<14}  {",".join(s.singularities) or "-"}')
    if not solutions:
        print(f'{PROG}: no solution: {result.reason}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    return EXIT_OK


# ------------------------------------------------------------------------------ design
def _tension_limits(args: argparse.Namespace) -> tuple[float, float]:
    t_min, t_max = args.tension_limits
    if not t_min > 0.0:
        raise ValueError(f'--tension-limits: MIN must be > 0 N, got {t_min:g}')
    if not t_max > t_min:
        raise ValueError(f'--tension-limits: MAX must exceed MIN, got {t_min:g} {t_max:g}')
    return t_min, t_max


def read_target_stiffness(path: str | Path) -> FloatArray:
    """The target K_c (6, 6) of a YAML file: key ``cartesian_stiffness`` with 6 rows of 6
    values or 36 values row-major (rows [fx fy fz mx my mz], columns [dx dy dz rx ry rz])."""
    document = config.load_yaml(path)
    if not isinstance(document, dict) or 'cartesian_stiffness' not in document:
        raise ValueError(f'--target-stiffness {path}: needs a "cartesian_stiffness" key '
                         '(6 rows of 6 values or 36 values, row-major)')
    try:
        values = np.asarray(document['cartesian_stiffness'], dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f'--target-stiffness {path}: cartesian_stiffness must be 36 numbers '
                         '(6 rows of 6 or flat, row-major)') from None
    if values.size != 36 or values.shape not in ((36,), (6, 6)):
        raise ValueError(f'--target-stiffness {path}: cartesian_stiffness must be 6x6 or 36 '
                         f'values, got shape {values.shape}')
    if not np.all(np.isfinite(values)):
        raise ValueError(f'--target-stiffness {path}: cartesian_stiffness must be finite')
    return values.reshape(6, 6)


def _cmd_design(args: argparse.Namespace) -> int:
    model, path, _ = _load_joint(args)
    xi = _screw(args, model)
    W = np.asarray(args.wrench, dtype=np.float64)
    t_min, t_max = _tension_limits(args)
    target = None
    if args.target_stiffness is not None:
        target = read_target_stiffness(args.target_stiffness)
    elif args.scale_stiffness is not None:
        if not args.scale_stiffness > 0.0:
            raise ValueError(f'--scale-stiffness must be > 0, got {args.scale_stiffness:g}')
        base = design.design_rest_lengths(model, xi, W, t_min, t_max,
                                          length_scale=args.length_scale)
        if base.success:
            target = args.scale_stiffness * base.cartesian_stiffness
    result = design.design_rest_lengths(model, xi, W, t_min, t_max, target,
                                        args.length_scale)
    strings = [{'name': name, 'length': float(length), 'rest_length': float(l0),
                'tension': float(t)}
               for name, length, l0, t in zip(
                   model.string_names, model.lengths(xi), result.rest_lengths, result.tensions,
                   strict=True)]
    report: dict[str, Any] = {
        'config': str(path), 'force_law': model.force_law, 'screw': xi, 'external_wrench': W,
        'tension_limits': [t_min, t_max], 'success': result.success,
        'message': result.message, 'rest_lengths': result.rest_lengths,
        'tensions': result.tensions, 'strings': strings,
        'cartesian_stiffness': result.cartesian_stiffness, 'stiffness': result.stiffness,
        'target_stiffness': target, 'stiffness_error': result.stiffness_error,
        'length_scale': result.length_scale, 'stable': result.stable}
    if args.json:
        _print_json(report)
    else:
        print(f"design at screw {_vector(_display(xi))} under W = {_vector(W)} (N, N m), "
              f'tensions in [{t_min:g}, {t_max:g}] N: {result.message}')
        if result.success:
            print()
            print(f"  {'name':<14}{'length (m)':>13}{'rest (m)':>13}{'tension (N)':>13}")
            for s in strings:
                print(f"  {s['name']:<14}{_num(s['length'], 13)}{_num(s['rest_length'], 13)}"
                      f"{_num(s['tension'], 13)}")
            print()
            print('achieved Cartesian stiffness K_c; columns: spatial twist in {1}, linear '
                  'first:')
            print('\n'.join(_matrix_lines(result.cartesian_stiffness, ROW_NAMES,
                                          KC_COLUMN_NAMES)))
            if target is not None:
                print(f'  stiffness error |S (K_c - K*) S| / |S K* S| = '
                      f'{_num(result.stiffness_error)} (L = {_num(result.length_scale)} m)')
            print(f'  stable: {_yes(result.stable)}')
    if not result.success:
        print(f'{PROG}: no design: {result.message}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    return EXIT_OK


# ------------------------------------------------------------------------------ plots
def _out_path(args: argparse.Namespace, figure: str) -> Path:
    return Path(args.out) if args.out else Path(FIGURE_FILES[figure])


def _report_png(path: Path, started: float) -> None:
    size = png_size(path)
    print(f'wrote {path} ({size[0]}x{size[1]} px, {time.perf_counter() - started:.2f} s)')


def png_size(path: str | Path) -> tuple[int, int]:
    """(width, height) in pixels from a PNG file's IHDR header."""
    import struct

    with open(path, 'rb') as handle:
        head = handle.read(24)
    if len(head) < 24 or head[:8] != b'\x89PNG\r\n\x1a\n' or head[12:16] != b'IHDR':
        raise ValueError(f'{path} is not a PNG file')
    width, height = struct.unpack('>II', head[16:24])
    return int(width), int(height)


def _draw(figure: str, args: argparse.Namespace, path: Path, size: tuple[int, int],
          progress: Callable[[int, int], None] | None) -> Path:
    """Compute and write one figure (the plots module is imported here: it needs matplotlib)."""
    w, h = size
    if figure == 'joint':
        model, _, rest = _load_joint(args)
        return plots.plot_joint(model, _screw(args, model), path, rest_lengths=rest, width=w,
                                height=h, elevation=args.elevation, azimuth=args.azimuth)
    if figure == 'extension':
        model, _, rest = _load_joint(args)
        sweep = sweeps.extension_sweep(model, args.extent, args.samples, rest, progress=progress)
        return plots.plot_extension_sweep(sweep, path, width=w, height=h)
    if figure == 'spine':
        chain, _, screws, W, _ = _chain_configuration(args)
        return plots.plot_spine(chain, screws, path, width=w, height=h, tip_wrench=W,
                                elevation=args.elevation, azimuth=args.azimuth)
    if figure == 'theta2':
        mech = _planar(args, {k: v for k, v in plots.PLANAR_THETA2_PARAMETERS.items()
                              if k in PLANAR_KEYS})
        return plots.plot_theta2_curves(mech, path, L3=args.L3, theta1=args.theta1,
                                        theta2_min=mech.theta2_min, theta2_max=mech.theta2_max,
                                        samples=args.samples, width=w, height=h)
    mech = _planar(args, plots.PLANAR_MAP_PARAMETERS)
    if figure == 'actuator-workspace':
        return plots.plot_actuator_workspace(mech, path, samples=args.samples, width=w,
                                             height=h)
    if figure == 'cartesian-workspace':
        return plots.plot_cartesian_workspace(mech, path, samples=args.samples,
                                              resolution=args.resolution, width=w, height=h,
                                              progress=progress)
    if figure == 'actuator-stiffness':
        return plots.plot_actuator_stiffness(mech, path, resolution=args.resolution, width=w,
                                             height=h, progress=progress)
    if figure == 'cartesian-stiffness':
        return plots.plot_cartesian_stiffness(mech, path, resolution=args.resolution,
                                              samples=args.samples, width=w, height=h,
                                              progress=progress)
    if figure == 'stiffness-range':
        model, _, _ = _load_joint(args)
        t_min, t_max = _tension_limits(args)
        return plots.plot_stiffness_range(model, _screw(args, model), path,
                                          coordinate=args.coordinate, extent=args.extent,
                                          samples=args.samples, external_wrench=args.wrench,
                                          tension_min=t_min, tension_max=t_max, width=w,
                                          height=h, progress=progress)
    raise ValueError(f'unknown figure {figure!r}')  # unreachable: argparse checks the choice


def _cmd_plot(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    path = _out_path(args, args.figure)
    progress = TerminalProgress(args.figure)
    _draw(args.figure, args, path, tuple(args.size), progress)
    progress.finish()
    _report_png(path, started)
    return EXIT_OK


def _figure_defaults(figure: str) -> argparse.Namespace:
    """The options of ``plot <figure>`` with their defaults (as if typed without options)."""
    return build_parser().parse_args(['plot', figure])


def _cmd_figures(args: argparse.Namespace) -> int:
    lo, hi = SCALE_RANGE
    if not lo <= args.scale <= hi:
        raise ValueError(f'--scale must be in [{lo:g}, {hi:g}], got {args.scale:g}')
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    names = list(FIGURE_FILES)
    for k, figure in enumerate(names):
        started = time.perf_counter()
        options = _figure_defaults(figure)
        if figure == 'joint':
            options.screw = list(README_JOINT_SCREW)
        if args.resolution is not None:
            for attr in ('resolution', 'samples'):
                if hasattr(options, attr):
                    setattr(options, attr, max(args.resolution, 2))
        w, h = plots.DEFAULT_SIZES[figure]
        size = (round(w * args.scale), round(h * args.scale))
        path = out / FIGURE_FILES[figure]
        progress = TerminalProgress(f'[{k + 1}/{len(names)}] {figure}')
        _draw(figure, options, path, size, progress)
        progress.finish()
        _report_png(path, started)
    return EXIT_OK


def _cmd_bag(args: argparse.Namespace) -> int:
    from tensegrity_stiffness.recordings import bag

    progress = TerminalRateProgress('bag', unit=' inputs/s')
    try:
        summary = bag.process_bag(
            args.input, args.out, config_path=args.config, namespace=args.namespace,
            storage=args.storage, csv_path=args.csv, topics=args.topics,
            overwrite=args.overwrite, node=args.node, progress=progress)
    except ImportError as exc:  # rosbags not installed
        raise ValueError(f'the bag command needs rosbags ({exc})') from None
    finally:
        progress.finish()
    report = summary.to_dict()
    if args.json:
        _print_json(report)
        return EXIT_OK
    inputs = ', '.join(f'{n} {k}' for k, n in report['inputs'].items())
    answered = ', '.join(f'{n} {k}' for k, n in report['answered'].items())
    print(f"read {report['input']}: {inputs}")
    print(f"answered {report['answers']} inputs ({answered}) in {report['seconds']:.2f} s"
          + (f" ({report['inputs_per_second']:.0f} inputs/s)"
             if report['inputs_per_second'] else ''))
    print(f"wrote {report['output']} ({report['storage']}): "
          + ', '.join(f'{t} {n}' for t, n in report['written'].items()))
    if report['csv']:
        print(f"wrote {report['csv']}: {report['answers']} rows")
    if report['rejected']:
        print(f"skipped {report['rejected_total']} bad messages:")
        for kind, n in report['rejected'].items():
            print(f"  {kind}: {n} (e.g. {report['rejection_examples'][kind]})")
    return EXIT_OK


# ------------------------------------------------------------------------------ calibration
def _noise_option(text: str) -> tuple[str, float]:
    kind, sep, value = text.partition('=')
    if not sep:
        raise argparse.ArgumentTypeError(f"expected KIND=STD, got '{text}'")
    return kind.strip(), parse_number(value)


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from tensegrity_stiffness.cli import calibration_report

    bars: list[TerminalProgress] = []

    def progress(label: str) -> TerminalProgress:
        bars.append(TerminalProgress(f'calibrate: {label}'))
        return bars[-1]

    topics = {'pose': args.pose_topic, 'rest_lengths': args.rest_lengths_topic,
              'tensions': args.tensions_topic, 'wrench': args.wrench_topic,
              'lengths': args.lengths_topic}
    required = [name for name, topic in topics.items() if topic is not None]
    topics = {k: v for k, v in topics.items() if v is not None}
    try:
        result, report, lines = calibration_report.run(
            args.recording, args.config, fmt=args.format, topics=topics, required=required,
            fit=args.fit, noise=dict(args.noise or []), loss=args.loss,
            rule={'window': args.window, 'max_speed': args.max_speed,
                  'max_angular_speed': args.max_angular_speed},
            max_age=args.max_age, out=args.out, plot=args.plot, progress=progress)
    except ImportError as exc:  # rosbags not installed
        raise ValueError(f'reading a bag needs rosbags ({exc})') from None
    finally:
        for bar in bars:
            bar.finish()
    if args.json:
        _print_json(report)
    else:
        print('\n'.join(lines))
    return EXIT_OK if result.success else EXIT_NO_SOLUTION


# ------------------------------------------------------------------------------ chains
#: Tip wrench of the spine figure (docs/figures.md) (N, N m in the base frame): a sideways push.
README_SPINE_TIP_WRENCH = (0.1, 0.0, 0.0, 0.0, 0.0, 0.0)


def _chain_configuration(args: argparse.Namespace
                         ) -> tuple[JointChain, Path, FloatArray, FloatArray, Any]:
    """(chain, config path, screws, tip wrench, equilibrium result or None) of --config,
    --screws, --tip-wrench, --gravity: the given screws, else the chain equilibrium."""
    path = Path(args.config) if args.config else config.packaged_config_path(
        DEFAULT_SPINE_CONFIG)
    try:
        chain = JointChain.from_yaml(path)
    except ValueError as exc:
        raise ValueError(f'config {path}: {exc}') from None
    W = np.asarray(args.tip_wrench, dtype=np.float64)
    if args.gravity is not None:
        chain.gravity = chain.resolved_gravity(np.asarray(args.gravity, dtype=np.float64))
    if args.screws is not None:
        values = np.asarray(args.screws, dtype=np.float64)
        if values.size != 6 * chain.n_joints:
            raise ValueError(f'--screws needs 6 N = {6 * chain.n_joints} values (joint-major '
                             f'[wx wy wz vx vy vz]), got {values.size}')
        return chain, path, values.reshape(chain.n_joints, 6), W, None
    result = solve_chain_equilibrium(chain, W, time_budget=args.time_budget)
    return chain, path, result.screws, W, result


def _cmd_chain(args: argparse.Namespace) -> int:
    chain, path, screws, W, result = _chain_configuration(args)
    state = chain.evaluate(screws)
    residuals = chain.residuals(screws, W)
    report: dict[str, Any] = {
        'config': str(path), 'n_joints': chain.n_joints, 'tip_wrench': W,
        'gravity': chain.gravity, 'link_masses': chain.link_masses,
        'solved': result is not None,
        'success': True if result is None else result.success,
        'message': 'evaluated at the given screws' if result is None else result.message,
        'iterations': 0 if result is None else result.iterations,
        'residual': float(np.linalg.norm(residuals)), 'screws': screws,
        'joint_wrenches': state.wrenches,
        'slack_strings': [int(np.count_nonzero(s)) for s in state.slack],
        'tip_transform': state.tip_transform, 'tip_position': state.tip_transform[:3, 3],
        'tip_quaternion': rotation_to_quaternion(state.tip_transform[:3, :3]),
        'base_frame': chain.base_frame, 'tool_frame': chain.tool_frame}
    try:
        K = chain.tip_stiffness_from_state(state, W)
        report['tip_stiffness'] = K
        report['tip_stiffness_tool'] = chain.tip_stiffness_from_state(state, W, frame='tool')
        report['stable'] = is_stable(chain.tangent_stiffness(screws, W))
    except np.linalg.LinAlgError:
        report['tip_stiffness'] = report['tip_stiffness_tool'] = None
        report['stable'] = False
    if args.json:
        _print_json(report)
    else:
        _print_chain(report)
    if not report['success']:
        print(f'{PROG}: no equilibrium found: {report["message"]}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    return EXIT_OK


def _cmd_export_mjcf(args: argparse.Namespace) -> int:
    from tensegrity_stiffness.simulation.twin import export_mjcf

    text = export_mjcf(args.config, spine=args.spine, max_length=args.max_length)
    if args.out:
        Path(args.out).write_text(text)
        print(f'{PROG}: wrote {args.out}; view it with: python -m mujoco.viewer --mjcf '
              f'{args.out}', file=sys.stderr)
    else:
        sys.stdout.write(text)
    return EXIT_OK


def _print_chain(report: dict[str, Any]) -> None:
    print(f"chain: {report['config']} ({report['n_joints']} joints)")
    print(f"tip wrench W (N, N m, base frame): {_vector(report['tip_wrench'])}; gravity "
          f"{_vector(report['gravity'])} m/s^2, link masses {_vector(report['link_masses'])} kg")
    what = 'equilibrium' if report['solved'] else 'configuration'
    print(f"{what}: {report['message']}; residual {_num(report['residual'])}, iterations "
          f"{report['iterations']}, stable: {_yes(report['stable'])}")
    print()
    print('  joint' + ''.join(c.rjust(CELL_WIDTH) for c in COLUMN_NAMES) + '  slack')
    for i, (xi, slack) in enumerate(zip(_display(report['screws']), report['slack_strings'],
                                        strict=True)):
        print(f'  {i + 1:>5}' + ''.join(_num(float(v), CELL_WIDTH) for v in xi) + f'  {slack:>5}')
    print()
    print(f"tip pose in {report['base_frame']}: position (m) "
          f"{_vector(_display(report['tip_position']))}, quaternion [x y z w] "
          f"{_vector(_display(report['tip_quaternion']))}")
    for key, frame in (('tip_stiffness', f"base frame ({report['base_frame']})"),
                       ('tip_stiffness_tool', f"tool frame ({report['tool_frame']})")):
        print()
        if report[key] is None:
            print(f'tip stiffness in the {frame}: singular')
            continue
        print(f'tip stiffness dW/d[dv; dw] in the {frame}; rows: wrench (N, N m), columns: '
              'tip twist, linear first:')
        print('\n'.join(_matrix_lines(np.asarray(report[key]), ROW_NAMES, KC_COLUMN_NAMES)))


def _add_chain_options(p: argparse.ArgumentParser, tip_wrench: Sequence[float]) -> None:
    g = p.add_argument_group('chain')
    g.add_argument('--config', metavar='YAML',
                   help='spine config (ROS parameter file or plain YAML with "joint" and '
                        '"chain"; default: the packaged config/default_spine.yaml)')
    g.add_argument('--screws', nargs='+', type=parse_number, metavar='XI',
                   help='6 N values, joint-major [wx wy wz vx vy vz] (default: the chain '
                        'equilibrium under --tip-wrench and the weights)')
    g.add_argument('--tip-wrench', nargs=6, type=parse_number, default=list(tip_wrench),
                   metavar=('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'),
                   help='wrench on the last link in the base frame about its origin (N, N m; '
                        f'default {" ".join(f"{v:g}" for v in tip_wrench)})')
    g.add_argument('--gravity', nargs=3, type=parse_number, metavar=('GX', 'GY', 'GZ'),
                   help="gravity in the base frame (m/s^2; default: the config's; acts on "
                        'chain.link_masses)')
    g.add_argument('--time-budget', type=parse_number, metavar='S',
                   help='bound on the equilibrium solve (s; default: none)')


# ------------------------------------------------------------------------------ parser
def _add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument('--json', action='store_true', help='machine-readable JSON output')


def _add_joint_options(p: argparse.ArgumentParser, screw: bool = True) -> None:
    g = p.add_argument_group('joint')
    g.add_argument('--config', metavar='YAML',
                   help='joint config: plain YAML with a "joint" mapping or a ROS parameter '
                        'file (default: the packaged config/default_joint.yaml)')
    g.add_argument('--rest-lengths', nargs='+', type=parse_number, metavar='L0',
                   help='rest lengths (m): one for all strings or one per string, config order')
    g.add_argument('--force-law', choices=FORCE_LAWS,
                   help="string force law (default: the config's; 'paper' = the authors' code)")
    if screw:
        s = g.add_mutually_exclusive_group()
        s.add_argument('--screw', nargs=6, type=parse_number,
                       metavar=('WX', 'WY', 'WZ', 'VX', 'VY', 'VZ'),
                       help="screw xi = [omega; v] (rad, m); default: the config's "
                            'initial_screw (unloaded equilibrium)')
        s.add_argument('--pose', nargs=7, type=parse_number,
                       metavar=('X', 'Y', 'Z', 'QX', 'QY', 'QZ', 'QW'),
                       help='pose of link 2 in {1}: position (m) and unit quaternion (ROS '
                            'order); turned into the screw nearest the initial screw')


def _add_design_options(p: argparse.ArgumentParser, limits_required: bool) -> None:
    g = p.add_argument_group('joint')
    g.add_argument('--config', metavar='YAML',
                   help='joint config (default: the packaged config/default_joint.yaml)')
    g.add_argument('--force-law', choices=FORCE_LAWS,
                   help="string force law (default: the config's)")
    s = g.add_mutually_exclusive_group()
    s.add_argument('--screw', nargs=6, type=parse_number,
                   metavar=('WX', 'WY', 'WZ', 'VX', 'VY', 'VZ'),
                   help="target screw xi = [omega; v] (rad, m); default: the config's "
                        'initial_screw')
    s.add_argument('--pose', nargs=7, type=parse_number,
                   metavar=('X', 'Y', 'Z', 'QX', 'QY', 'QZ', 'QW'),
                   help='target pose of link 2 in {1}: position (m) and unit quaternion '
                        '(ROS order), on the branch nearest the initial screw')
    p.add_argument('--wrench', nargs=6, type=parse_number, default=[0.0] * 6,
                   metavar=('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'),
                   help='external wrench on link 2 in {1} about its origin (N, N m; default 0)')
    p.add_argument('--tension-limits', nargs=2, type=parse_number, metavar=('MIN', 'MAX'),
                   required=limits_required,
                   default=None if limits_required else [design.DEFAULT_TENSION_MIN,
                                                         design.DEFAULT_TENSION_MAX],
                   help='string tension limits (N), 0 < MIN < MAX'
                        + ('' if limits_required else ' (default 0.1 1.5)'))
    p.set_defaults(rest_lengths=None)


def _add_planar_options(p: argparse.ArgumentParser, defaults: str, config: bool) -> None:
    g = p.add_argument_group('planar mechanism', f'defaults: {defaults}')
    if config:
        g.add_argument('--config', metavar='YAML',
                       help='read the "planar" section of this config (default: the packaged '
                            'config/default_joint.yaml)')
    units = {'L': 'm', 'K1': 'N/m', 'K2': 'N/m', 'L3_min': 'm', 'L3_max': 'm',
             'theta1_min': 'rad', 'theta1_max': 'rad', 'theta2_min': 'rad', 'theta2_max': 'rad'}
    for key in PLANAR_KEYS:
        g.add_argument('--' + key.replace('_', '-'), dest=f'planar_{key}', type=parse_number,
                       metavar='VALUE',
                       help=f'{key} ({units[key]})')


def _add_plot_common(p: argparse.ArgumentParser, figure: str) -> None:
    from_sizes = plots.DEFAULT_SIZES[figure]
    p.add_argument('--out', metavar='PNG',
                   help=f'output file (default: ./{FIGURE_FILES[figure]})')
    p.add_argument('--size', nargs=2, type=_positive_int, default=list(from_sizes),
                   metavar=('W', 'H'),
                   help=f'PNG size in pixels (default: {from_sizes[0]} {from_sizes[1]})')


PLOT_HELP = {
    'joint': 'the joint in 3D at a screw or pose: nodes, strings coloured by tension, slack '
             'dashed',
    'extension': 'block Frobenius norms and column norms of K along an extensional '
                 'displacement from the unloaded equilibrium (Monke & Vikas Figs. 4-5)',
    'actuator-workspace': 'actuator workspace with the singular curves i-vi (Ji, Li & Lin '
                          'Fig. 2)',
    'cartesian-workspace': 'Cartesian workspace with the singular curves i-vi (Fig. 3)',
    'theta2': 'U, tau and K against theta2 with the actuators locked (Figs. 4-6)',
    'actuator-stiffness': 'stiffness map over the actuator workspace (Fig. 7)',
    'cartesian-stiffness': 'stiffness map over the Cartesian workspace (Fig. 8)',
    'stiffness-range': 'reachable range of each diagonal entry of K_c over the admissible '
                       'tensions along a sweep of one screw coordinate',
    'spine': 'a spine of joints in 3D at screws or at its equilibrium under a tip wrench: '
             'strings coloured by tension',
}
def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of every subcommand."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Stiffness of tensegrity joints (Monke & Vikas) and of the '
        'planar tensegrity mechanism (Ji, Li & Lin) from the command line. Numbers accept pi '
        'arithmetic (pi/10).',
        epilog='exit codes: 0 ok, 1 no solution, 2 bad input, 3 matplotlib missing')
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')

    p = sub.add_parser('joint', help='wrench, K, K_c, tensions, interpretation at a screw/pose',
                       description='Evaluate the joint at a screw or pose (eqs. 6-11, 19-20).')
    _add_joint_options(p)
    _add_json(p)
    p.set_defaults(handler=_cmd_joint)

    p = sub.add_parser('equilibrium', help='equilibrium under an external wrench',
                       description='Solve F(xi) + W = 0 for the external wrench W on link 2 '
                                   '(in {1} about its origin) and report the joint there.')
    p.add_argument('--wrench', nargs=6, type=parse_number, required=True,
                   metavar=('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'), help='W (N, N m)')
    _add_joint_options(p, screw=False)
    p.add_argument('--initial-screw', nargs=6, type=parse_number, metavar='XI',
                   help="start of the solve (default: the config's initial_screw)")
    p.add_argument('--time-budget', type=parse_number, metavar='S',
                   help='bound on the solve time (s; default: none)')
    _add_json(p)
    p.set_defaults(handler=_cmd_equilibrium)

    p = sub.add_parser('planar-fk', help='planar mechanism forward kinematics',
                       description='Stable equilibrium, stiffness, Jacobian and singular '
                                   'conditions at actuator (L3, theta1).')
    p.add_argument('L3', type=parse_number, help='actuator length (m)')
    p.add_argument('theta1', type=parse_number, help='actuator angle (rad), e.g. pi/10')
    _add_planar_options(p, "the config's planar section (L = 1, K1 = 100, K2 = 10)", True)
    _add_json(p)
    p.set_defaults(handler=_cmd_planar_fk)

    p = sub.add_parser('planar-ik', help='planar mechanism inverse kinematics',
                       description='Actuator states (L3, theta1) holding D3 at (x, y) in '
                                   'stable equilibrium, stiffest first.')
    p.add_argument('x', type=parse_number, help='D3 x (m)')
    p.add_argument('y', type=parse_number, help='D3 y (m)')
    p.add_argument('--include-unstable', action='store_true',
                   help='also list unstable equilibria')
    p.add_argument('--require-theta2-in-range', action='store_true',
                   help='drop solutions with theta2 outside its range')
    _add_planar_options(p, "the config's planar section (L = 1, K1 = 100, K2 = 10)", True)
    _add_json(p)
    p.set_defaults(handler=_cmd_planar_ik)

    p = sub.add_parser('design', help='rest lengths for a pose, load, tension limits and '
                       'stiffness', description='Rest lengths that hold the target screw or pose '
                       'in equilibrium under the external wrench with every tension within the '
                       'limits and K_c closest to a target (exact convex QP).')
    _add_design_options(p, limits_required=True)
    t = p.add_mutually_exclusive_group()
    t.add_argument('--target-stiffness', metavar='FILE.yaml',
                   help='target K_c: YAML with "cartesian_stiffness", 6 rows of 6 or 36 values '
                        '(row-major; N/m, N, N m/m, N m/rad)')
    t.add_argument('--scale-stiffness', type=parse_number, metavar='F',
                   help='target K_c = F times the K_c of the mid-limit design (no target)')
    p.add_argument('--length-scale', type=parse_number, metavar='M',
                   help='L of S = diag(1, 1, 1, 1/L, 1/L, 1/L) (m; default: the largest '
                        'distance of a link-1 node from the origin of {1})')
    _add_json(p)
    p.set_defaults(handler=_cmd_design)

    p = sub.add_parser('plot', help='write one figure as PNG (needs matplotlib)',
                       description='Write one figure as PNG (needs matplotlib).')
    figures = p.add_subparsers(dest='figure', required=True, metavar='FIGURE')
    for figure, text in PLOT_HELP.items():
        f = figures.add_parser(figure, help=text, description=text + '.')
        _add_plot_common(f, figure)
        if figure == 'joint':
            _add_joint_options(f)
            f.add_argument('--elevation', type=parse_number, default=18.0, metavar='DEG',
                           help='view elevation (degrees, default 18)')
            f.add_argument('--azimuth', type=parse_number, default=-50.0, metavar='DEG',
                           help='view azimuth (degrees, default -50)')
        elif figure == 'extension':
            _add_joint_options(f, screw=False)
            f.add_argument('--extent', type=parse_number, metavar='M',
                           help='largest extension (m; default: the smallest maximum stretch '
                                'lmax - l0 of the strings)')
            f.add_argument('--samples', type=_positive_int,
                           default=sweeps.DEFAULT_SWEEP_SAMPLES,
                           help=f'points along the sweep (default '
                                f'{sweeps.DEFAULT_SWEEP_SAMPLES})')
        elif figure == 'spine':
            _add_chain_options(f, README_SPINE_TIP_WRENCH)
            f.add_argument('--elevation', type=parse_number, default=12.0, metavar='DEG',
                           help='view elevation (degrees, default 12)')
            f.add_argument('--azimuth', type=parse_number, default=-60.0, metavar='DEG',
                           help='view azimuth (degrees, default -60)')
        elif figure == 'theta2':
            _add_planar_options(f, 'L = 1, K1 = 100, K2 = 10, theta2 in [0, pi] (Figs. 4-6)',
                                False)
            f.add_argument('--L3', type=parse_number, default=6.0, metavar='M',
                           help='locked actuator length (m, default 6)')
            f.add_argument('--theta1', type=parse_number, default=math.pi / 10, metavar='RAD',
                           help='locked actuator angle (rad, default pi/10)')
            f.add_argument('--samples', type=_positive_int,
                           default=plots.DEFAULT_THETA2_SAMPLES,
                           help=f'theta2 samples (default {plots.DEFAULT_THETA2_SAMPLES})')
        elif figure == 'stiffness-range':
            _add_design_options(f, limits_required=False)
            f.add_argument('--coordinate', choices=plots.SCREW_COORDINATES, default='wx',
                           help='screw coordinate swept about the screw (default wx)')
            f.add_argument('--extent', type=parse_number, default=0.3, metavar='OFFSET',
                           help='sweep from -OFFSET to +OFFSET (rad or m; default 0.3)')
            f.add_argument('--samples', type=_positive_int, default=plots.DEFAULT_RANGE_SAMPLES,
                           help=f'points along the sweep (default '
                                f'{plots.DEFAULT_RANGE_SAMPLES})')
        else:
            _add_planar_options(f, 'L = 1, K1 = 200, K2 = 100, L3 in [0, 2L], theta1 in '
                                   '[0, pi] (Figs. 2-3, 7-8)', False)
            if figure != 'actuator-stiffness':
                f.add_argument('--samples', type=_positive_int,
                               default=plots.DEFAULT_CURVE_SAMPLES,
                               help=f'samples per curve (default '
                                    f'{plots.DEFAULT_CURVE_SAMPLES})')
            if figure != 'actuator-workspace':
                f.add_argument('--resolution', type=_positive_int,
                               default=plots.DEFAULT_MAP_RESOLUTION,
                               help=f'grid points per side (default '
                                    f'{plots.DEFAULT_MAP_RESOLUTION})')
    p.set_defaults(handler=_cmd_plot)

    p = sub.add_parser('bag', help='wrench and stiffness for a whole rosbag2 recording',
                       description="Read the node's inputs (screw, pose, rest_lengths) from a "
                                   'rosbag2 (mcap or sqlite3) and write what stiffness_node '
                                   'would publish (wrench, stiffness, cartesian_stiffness, '
                                   'string_tensions, stiffness_interpretation) to a new rosbag2, '
                                   'each answer at the log time of its input (needs rosbags); '
                                   "with --node spine, spine_node's topics.")
    p.add_argument('input', metavar='INPUT', help='rosbag2 folder (or a .mcap / .db3 file)')
    p.add_argument('--out', required=True, metavar='OUTPUT', help='rosbag2 folder to write')
    p.add_argument('--node', choices=('stiffness', 'spine'), default='stiffness',
                   help='the node whose topics are processed: stiffness_node (default; inputs '
                        'screw, pose, rest_lengths) or spine_node (inputs screws, poses, '
                        'rest_lengths; outputs joint_wrenches joint_stiffness '
                        'joint_cartesian_stiffness tip_pose tip_wrench tip_stiffness '
                        'tip_stiffness_base)')
    p.add_argument('--config', metavar='YAML',
                   help="the node's parameter file (default: the packaged "
                        'config/default_joint.yaml, with --node spine '
                        'config/default_spine.yaml; a file overrides the parameters it has)')
    p.add_argument('--namespace', default=None, metavar='NS',
                   help="the node's topics' prefix (default /stiffness_node, with --node spine "
                        '/spine_node: the node in the root namespace)')
    p.add_argument('--storage', metavar='mcap|sqlite3',
                   help="storage of OUTPUT (default: the input's)")
    p.add_argument('--csv', metavar='FILE', help='also write one row per answered input')
    p.add_argument('--topics', nargs='+', metavar='TOPIC',
                   help='outputs to write (default all: wrench stiffness cartesian_stiffness '
                        'string_tensions stiffness_interpretation)')
    p.add_argument('--overwrite', action='store_true',
                   help='replace OUTPUT (a rosbag2) and FILE if they exist')
    _add_json(p)
    p.set_defaults(handler=_cmd_bag)
    p = sub.add_parser('calibrate', help="each string's stiffness and rest-length offset from "
                       'a recording', description=(
                           "Fit each string's stiffness and rest-length offset to the "
                           'quasi-static instants of a recording (rosbag2 mcap/sqlite3, or CSV '
                           'with the columns of '
                           'tensegrity_stiffness.recordings.calibration_recording), '
                           'print the table and the residuals, write a calibrated config and a '
                           'residual plot. Exit 1 when the fit does not converge.'))
    p.add_argument('recording', metavar='RECORDING',
                   help='rosbag2 folder (or .mcap / .db3 file), or a .csv file')
    p.add_argument('--config', metavar='YAML',
                   help='nominal joint config (default: the packaged default_joint.yaml)')
    p.add_argument('--format', choices=('bag', 'csv'),
                   help='recording format (default: csv for a .csv file, else bag)')
    from tensegrity_stiffness.estimation.calibration import FIT_KINDS, LOSSES
    from tensegrity_stiffness.recordings.calibration_recording import (
        DEFAULT_MAX_ANGULAR_SPEED,
        DEFAULT_MAX_SPEED,
        DEFAULT_TOPICS,
        DEFAULT_WINDOW,
    )
    for name, text in (('pose', 'PoseStamped or PoseWithCovarianceStamped of link 2 in {1}'),
                       ('rest-lengths', 'Float64MultiArray of the commanded rest lengths'),
                       ('tensions', 'Float64MultiArray of load-cell tensions, NaN = none'),
                       ('wrench', 'WrenchStamped on link 2 in {1}'),
                       ('lengths', 'Float64MultiArray of measured string lengths, NaN = none')):
        p.add_argument(f'--{name}-topic', metavar='TOPIC',
                       help=f"{text} (default {DEFAULT_TOPICS[name.replace('-', '_')]}"
                            + ('' if name == 'rest-lengths' else ', used when present')
                            + '; given: required)')
    p.add_argument('--fit', nargs='+', choices=FIT_KINDS, default=list(FIT_KINDS),
                   help='parameters to fit (default both)')
    p.add_argument('--noise', nargs='+', type=_noise_option, metavar='KIND=STD',
                   help='measurement std: position (m), rotation (rad), force (N), moment '
                        '(N m), tension (N), length (m) (defaults 1e-4, 0.1 deg, 0.01, 5e-4, '
                        '0.005, 1e-4)')
    p.add_argument('--loss', choices=LOSSES, default='soft_l1',
                   help='robust loss (default soft_l1; linear: plain least squares)')
    p.add_argument('--window', type=parse_number, default=DEFAULT_WINDOW, metavar='S',
                   help=f'quasi-static: rest lengths held and pose still for this long '
                        f'(default {DEFAULT_WINDOW} s)')
    p.add_argument('--max-speed', type=parse_number, default=DEFAULT_MAX_SPEED, metavar='M/S',
                   help=f'quasi-static: largest mean pose speed (default {DEFAULT_MAX_SPEED})')
    p.add_argument('--max-angular-speed', type=parse_number, default=DEFAULT_MAX_ANGULAR_SPEED,
                   metavar='RAD/S', help='quasi-static: largest mean angular speed (default '
                                         f'{DEFAULT_MAX_ANGULAR_SPEED:.4g})')
    p.add_argument('--max-age', type=parse_number, default=0.1, metavar='S',
                   help='tensions and wrench older than this at a pose are not used '
                        '(default 0.1 s)')
    p.add_argument('--out', metavar='YAML', help='write the calibrated config here')
    p.add_argument('--plot', metavar='PNG', help='write the residual plot here (matplotlib)')
    _add_json(p)
    p.set_defaults(handler=_cmd_calibrate)

    p = sub.add_parser('chain', help='a spine of joints: tip pose and tip stiffness',
                       description='Tip pose and exact tip stiffness of a chain of joints at '
                                   '--screws (under the given loads), or at its equilibrium '
                                   'under --tip-wrench and the link weights.')
    _add_chain_options(p, (0.0,) * 6)
    _add_json(p)
    p.set_defaults(handler=_cmd_chain)

    p = sub.add_parser('export-mjcf', help="MuJoCo model (MJCF) of the joint or the spine",
                       description="Write the MuJoCo model of the digital twin "
                                   "(tensegrity_stiffness.simulation.twin) built from a config; "
                                   "open it with: python -m mujoco.viewer --mjcf FILE.xml")
    p.add_argument('--config', metavar='YAML', help='config file (default: the packaged '
                   'default_joint.yaml, or default_spine.yaml with --spine)')
    p.add_argument('--spine', action='store_true', help='the spine (a chain config)')
    p.add_argument('--out', metavar='FILE.xml', help='output file (default: standard output)')
    p.add_argument('--max-length', choices=('limit', 'ignore'), default='limit',
                   help="strings past lmax: 'limit' an inextensible stop (default), 'ignore' "
                        "Hooke's law goes on (docs/simulation.md)")
    p.set_defaults(handler=_cmd_export_mjcf)

    p = sub.add_parser('figures', help="regenerate every figure of docs/figures.md into a folder",
                       description='Write every figure at its default parameters (the '
                                   "papers' sets) into a folder (needs matplotlib).")
    p.add_argument('--out', default='docs/figures', metavar='DIR',
                   help='output folder (created if missing; default docs/figures)')
    p.add_argument('--scale', type=parse_number, default=1.0,
                   help='scale of the pixel sizes (default 1)')
    p.add_argument('--resolution', type=_positive_int, metavar='N',
                   help='override every grid resolution and sample count (quick previews)')
    p.set_defaults(handler=_cmd_figures)
    return parser


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush does not fail again."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # not a real file (e.g. captured in tests)
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tensegrity-stiffness``; returns the exit code (see the module docstring).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(_protect_negative_numbers(argv))
    except SystemExit as exc:  # --help (0) or a usage error (2, message already printed)
        return int(exc.code) if isinstance(exc.code, int) else EXIT_BAD_INPUT
    try:
        return args.handler(args)
    except plots.MatplotlibMissingError as exc:
        print(f'{PROG}: {exc}', file=sys.stderr)
        return EXIT_NO_MATPLOTLIB
    except ValueError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # e.g. piped into `head`: stop quietly (Python docs recipe)
        _silence_stdout()
        return EXIT_NO_SOLUTION
    except OSError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == '__main__':
    sys.exit(main())
