"""The commands on recordings and models: ``bag`` (what a node would publish, for a whole rosbag2
recording), ``calibrate`` (each string's stiffness and rest-length offset from a recording) and
``export-mjcf`` (the digital twin's MuJoCo model)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from tensegrity_stiffness.cli.common import (
    EXIT_NO_SOLUTION,
    EXIT_OK,
    PROG,
    add_json,
    parse_number,
    print_json,
)
from tensegrity_stiffness.cli.progress import ProgressBar


def add_allow_damaged(p: argparse.ArgumentParser) -> None:
    """``--allow-damaged``: go on with what a recording that stops being readable part way
    holds (default: exit 2 saying how much was read)."""
    p.add_argument('--allow-damaged', action='store_true',
                   help='a recording whose storage stops being readable part way: go on with '
                        'the messages read before (default: exit 2 saying how many were read)')


def _cmd_bag(args: argparse.Namespace) -> int:
    from tensegrity_stiffness.recordings import bag

    progress = ProgressBar('bag', unit='inputs')
    try:
        summary = bag.process_bag(
            args.input, args.out, config_path=args.config, namespace=args.namespace,
            output_namespace=args.output_namespace, storage=args.storage, csv_path=args.csv,
            topics=args.topics,
            overwrite=args.overwrite, node=args.node, progress=progress,
            allow_damaged=args.allow_damaged)
    except ImportError as exc:  # rosbags not installed
        raise ValueError(f'the bag command needs rosbags ({exc})') from None
    finally:
        progress.finish()
    report = summary.to_dict()
    if args.json:
        print_json(report)
        return EXIT_OK
    inputs = ', '.join(f'{n} {k}' for k, n in report['inputs'].items())
    answered = ', '.join(f'{n} {k}' for k, n in report['answered'].items())
    print(f"read {report['input']}: {inputs}")
    if report['damage']:
        print(f"{report['input']}: damaged: {report['messages_read']} of "
              f"{report['messages_total']} messages read ({report['damage']})")
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


def _noise_option(text: str) -> tuple[str, float]:
    kind, sep, value = text.partition('=')
    if not sep:
        raise argparse.ArgumentTypeError(f"expected KIND=STD, got '{text}'")
    return kind.strip(), parse_number(value)


#: ``calibrate`` options for a joint only (not with ``--structure``).
_JOINT_ONLY = ('config', 'pose_topic', 'wrench_topic', 'plot')


def _cmd_calibrate_structure(args: argparse.Namespace) -> int:
    from tensegrity_stiffness.cli import structure_calibration_report
    from tensegrity_stiffness.estimation.calibration_results import FIT_KINDS

    given = [name for name in _JOINT_ONLY if getattr(args, name) is not None]
    given += [name for name, default in (('fit', list(FIT_KINDS)), ('loss', 'soft_l1'))
              if getattr(args, name) != default]
    if given:
        raise ValueError(f"{' '.join('--' + name.replace('_', '-') for name in given)}: not "
                         "for a structure (--structure fits every string's stiffness and "
                         'offset from its lengths, load cells and encoders)')
    topics = {name: topic for name, topic in (
        ('rest_lengths', args.rest_lengths_topic), ('tensions', args.tensions_topic),
        ('lengths', args.lengths_topic)) if topic is not None}
    bar = ProgressBar('calibrate: read')
    try:
        _, report, lines = structure_calibration_report.run(
            args.recording, args.structure, fmt=args.format, topics=topics,
            noise=dict(args.noise or []),
            rule={'window': args.window, 'max_speed': args.max_speed}, max_age=args.max_age,
            out=args.out, progress=bar, allow_damaged=args.allow_damaged)
    except ImportError as exc:  # rosbags not installed
        raise ValueError(f'reading a bag needs rosbags ({exc})') from None
    finally:
        bar.finish()
    if args.json:
        print_json(report)
    else:
        print('\n'.join(lines))
    return EXIT_OK


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from tensegrity_stiffness.cli import calibration_report

    if args.structure:
        return _cmd_calibrate_structure(args)
    bars: list[ProgressBar] = []

    def progress(label: str) -> ProgressBar:
        bars.append(ProgressBar(f'calibrate: {label}'))
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
            max_age=args.max_age, out=args.out, plot=args.plot, progress=progress,
            allow_damaged=args.allow_damaged)
    except ImportError as exc:  # rosbags not installed
        raise ValueError(f'reading a bag needs rosbags ({exc})') from None
    finally:
        for bar in bars:
            bar.finish()
    if args.json:
        print_json(report)
    else:
        print('\n'.join(lines))
    return EXIT_OK if result.success else EXIT_NO_SOLUTION


def _cmd_export_mjcf(args: argparse.Namespace) -> int:
    if args.structure:
        from tensegrity_stiffness.structures.mjcf import structure_mjcf
        from tensegrity_stiffness.structures.structure import Structure

        text = structure_mjcf(Structure.from_yaml(args.structure))
    else:
        from tensegrity_stiffness.simulation.twin_model import export_mjcf

        text = export_mjcf(args.config, spine=args.spine, max_length=args.max_length)
    if args.out:
        Path(args.out).write_text(text)
        print(f'{PROG}: wrote {args.out}; view it with: python -m mujoco.viewer --mjcf '
              f'{args.out}', file=sys.stderr)
    else:
        sys.stdout.write(text)
    return EXIT_OK


def add_bag_parser(sub: Any) -> None:
    """``bag``."""
    p = sub.add_parser('bag', help='wrench and stiffness for a whole rosbag2 recording',
                       description="Read the node's inputs (screw, pose, rest_lengths) from a "
                                   'rosbag2 (mcap or sqlite3) and write what stiffness_node '
                                   'would publish (wrench, stiffness, cartesian_stiffness, '
                                   'string_tensions, stiffness_interpretation) to a new rosbag2, '
                                   'each answer at the log time of its input (needs rosbags); '
                                   "with --node spine, spine_node's topics; with --node "
                                   "structure, structure_node's.")
    p.add_argument('input', metavar='INPUT', help='rosbag2 folder (or a .mcap / .db3 file)')
    p.add_argument('--out', required=True, metavar='OUTPUT', help='rosbag2 folder to write')
    p.add_argument('--node', choices=('stiffness', 'spine', 'structure'), default='stiffness',
                   help='the node whose topics are processed: stiffness_node (default; inputs '
                        'screw, pose, rest_lengths) or spine_node (inputs screws, poses, '
                        'rest_lengths; outputs joint_wrenches joint_stiffness '
                        'joint_cartesian_stiffness tip_pose tip_wrench tip_stiffness '
                        'tip_stiffness_base tip_stiffness_stamped tip_stiffness_base_stamped) or '
                        'structure_node (inputs poses, pose_values, rest_lengths; outputs '
                        'body_wrenches stiffness string_tensions bar_forces contact_forces)')
    p.add_argument('--config', metavar='YAML',
                   help="the node's parameter file (default: the packaged "
                        'config/default_joint.yaml, with --node spine '
                        'config/default_spine.yaml; a file overrides the parameters it has; '
                        'with --node structure also a structure file, default the packaged '
                        'six_bar.yaml)')
    p.add_argument('--namespace', default=None, metavar='NS',
                   help="the input topics' prefix (default /stiffness_node, with --node spine "
                        '/spine_node, with --node structure /structure_node: the node in the '
                        'root namespace)')
    p.add_argument('--output-namespace', default=None, metavar='NS',
                   help='the outputs\' prefix (default: the node that would publish them: NS, '
                        'or, where NS ends in another node of the package (/twin/sim_node), '
                        'that name replaced by the node\'s (/twin/stiffness_node))')
    p.add_argument('--storage', metavar='mcap|sqlite3',
                   help="storage of OUTPUT (default: the input's)")
    p.add_argument('--csv', metavar='FILE', help='also write one row per answered input')
    p.add_argument('--topics', nargs='+', metavar='TOPIC',
                   help='outputs to write (default all: wrench stiffness cartesian_stiffness '
                        'string_tensions stiffness_interpretation stiffness_stamped '
                        'cartesian_stiffness_stamped)')
    add_allow_damaged(p)
    p.add_argument('--overwrite', action='store_true',
                   help='replace OUTPUT (a rosbag2) and FILE if they exist')
    add_json(p)
    p.set_defaults(handler=_cmd_bag)


def add_calibrate_parser(sub: Any) -> None:
    """``calibrate``."""
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
    p.add_argument('--structure', metavar='FILE',
                   help='calibrate this structure (a structure file or a packaged example, '
                        'docs/structures.md) from its string lengths, load cells and encoders '
                        '(default topics /structure_sim_node/measured_lengths, '
                        'measured_tensions, measured_rest_lengths; in a CSV the length_j, '
                        'tension_j and rest_length_j columns): each string\'s stiffness and '
                        'offset; --out writes the calibrated structure file')
    p.add_argument('--format', choices=('bag', 'csv'),
                   help='recording format (default: csv for a .csv file, else bag)')
    from tensegrity_stiffness.estimation.calibration_results import FIT_KINDS
    from tensegrity_stiffness.estimation.joint_calibration import LOSSES
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
                            + '; given: required'
                            + ('' if name in ('pose', 'wrench') else
                               '; --structure: /structure_sim_node/'
                               + {'rest-lengths': 'measured_rest_lengths (the encoders)',
                                  'tensions': 'measured_tensions',
                                  'lengths': 'measured_lengths'}[name]) + ')')
    p.add_argument('--fit', nargs='+', choices=FIT_KINDS, default=list(FIT_KINDS),
                   help='parameters to fit (default both)')
    p.add_argument('--noise', nargs='+', type=_noise_option, metavar='KIND=STD',
                   help='measurement std: position (m), rotation (rad), force (N), moment '
                        '(N m), tension (N), length (m) (defaults 1e-4, 0.1 deg, 0.01, 5e-4, '
                        '0.005, 1e-4; force=0 moment=0: the known loads are exact, '
                        'constraints; a zero load is always exact)')
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
    add_allow_damaged(p)
    p.add_argument('--out', metavar='YAML', help='write the calibrated config here')
    p.add_argument('--plot', metavar='PNG', help='write the residual plot here (matplotlib)')
    add_json(p)
    p.set_defaults(handler=_cmd_calibrate)


def add_export_mjcf_parser(sub: Any) -> None:
    """``export-mjcf``."""
    p = sub.add_parser('export-mjcf',
                       help='MuJoCo model (MJCF) of the joint, the spine or a structure',
                       description="Write the MuJoCo model of the digital twin "
                                   "(tensegrity_stiffness.simulation.twin) built from a joint or "
                                   "spine config, or with --structure of a structure file "
                                   "(tensegrity_stiffness.structures.mjcf); open it with: "
                                   "python -m mujoco.viewer --mjcf FILE.xml")
    p.add_argument('--config', metavar='YAML', help='config file (default: the packaged '
                   'default_joint.yaml, or default_spine.yaml with --spine)')
    p.add_argument('--spine', action='store_true', help='the spine (a chain config)')
    p.add_argument('--structure', metavar='YAML', help='a structure file (docs/structures.md): '
                   'its bodies, strings and ground instead of the joint or the spine '
                   '(--config, --spine and --max-length do not apply)')
    p.add_argument('--out', metavar='FILE.xml', help='output file (default: standard output)')
    p.add_argument('--max-length', choices=('limit', 'ignore'), default='limit',
                   help="the joint's or spine's strings past lmax: 'limit' an inextensible "
                        "stop (default), 'ignore' Hooke's law goes on (docs/simulation.md); a "
                        "structure's are always limited")
    p.set_defaults(handler=_cmd_export_mjcf)
