#!/usr/bin/env python3
"""Throughput of ``tensegrity-stiffness bag``, run by hand:
``python3 bench/bench_bag.py [--n N] [--repeat R] [--storage mcap|sqlite3] [--baseline CHECKOUT]``.

Writes a rosbag2 (default mcap) of N screws (default 100,000, 1 kHz log times, near the default
joint's unloaded equilibrium) to a temporary folder, then measures side by side in one run:
* end to end: :func:`tensegrity_stiffness.recordings.bag.process_bag` (read, decode and validate as
  the node does, batched evaluation, write five outputs per input), in inputs per second, best of R
  runs; with ``--baseline CHECKOUT`` (a checkout of another commit, e.g. a ``git worktree``) that
  checkout's ``tensegrity_stiffness/recordings/bag.py`` (``tensegrity_stiffness/bag.py`` before
  the subpackages) too, on this checkout's library (the parts it imports included), its runs
  interleaved with this one's, and the ratio;
* its parts, with the command's own pieces: reading and decoding (rosbags ``Reader.messages``,
  plain screws decoded in blocks with ``plain_screw_values`` and checked with
  ``stiffness_node.screw_inputs``); the library (``stiffness_node.joint_outputs_batch`` and
  ``finite_rows`` in the command's chunks, OpenBLAS on one thread as in the command);
  writing (the output templates' rows and ``write_blocks``: rosbags' ``Writer.write``, five
  messages per input); each part timed on its own (on a loaded machine they need not add up to
  the end-to-end time);
* for comparison, the per-message decoding the blocks replace (``deserialize_cdr`` +
  ``messages.multiarray_to_array`` per message), and the library with OpenBLAS's default
  thread count.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))

from support.bag_recordings import TYPESTORE, In, multiarray, screw_stream, write_bag  # noqa: E402

from tensegrity_stiffness.nodes import layouts, messages, stiffness_node  # noqa: E402
from tensegrity_stiffness.recordings import bag, bag_topics, bag_writers, screw_cdr  # noqa: E402


def load_bag_module(checkout: Path) -> object:
    """The bag command's module of another checkout (``tensegrity_stiffness/recordings/bag.py``,
    or ``tensegrity_stiffness/bag.py`` in a checkout of the flat layout) as a module of its own
    (it imports this checkout's library, its parts included)."""
    package = checkout / 'tensegrity_stiffness'
    path = package / 'recordings' / 'bag.py'
    if not path.is_file():
        path = package / 'bag.py'  # the flat layout before the subpackages
    spec = importlib.util.spec_from_file_location('baseline_bag', path)
    if spec is None or spec.loader is None:
        raise SystemExit(f'{path}: cannot load')
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--n', type=int, default=100_000, help='screws in the bag')
    parser.add_argument('--repeat', type=int, default=3, help='end-to-end runs of each')
    parser.add_argument('--storage', choices=bag_topics.STORAGES, default='mcap',
                        help="the input's storage (the output's follows)")
    parser.add_argument('--baseline', type=Path, metavar='CHECKOUT',
                        help="another checkout whose bag.py runs side by side")
    args = parser.parse_args()
    baseline = load_bag_module(args.baseline) if args.baseline else None
    n, chunk = args.n, bag_topics.CHUNK_SIZE
    screws = screw_stream(n, seed=0)
    settings = bag_topics.node_settings()
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / 'in'
        start = time.perf_counter()
        write_bag(src, [In('screw', 1_000_000 * (i + 1), multiarray(xi))
                        for i, xi in enumerate(screws)], args.storage)
        print(f'wrote {n} screws ({args.storage}) in {time.perf_counter() - start:.1f} s')

        runs: dict[str, list[float]] = {'this': [], 'baseline': []}
        modules = {'this': bag, 'baseline': baseline}
        for r in range(args.repeat):
            for name, module in modules.items():
                if module is None:
                    continue
                start = time.perf_counter()
                summary = module.process_bag(src, Path(tmp) / f'out_{name}_{r}')
                runs[name].append(time.perf_counter() - start)
                assert summary.answers == n, summary
        end_to_end = min(runs['this'])

        start = time.perf_counter()
        with Reader(src) as reader:
            raws = [raw for _, _, raw in reader.messages()]
        iterate = time.perf_counter() - start
        start = time.perf_counter()
        decoded = [stiffness_node.screw_inputs(screw_cdr.plain_screw_values(raws[k:k + chunk]))
                   for k in range(0, n, chunk)]
        decode = time.perf_counter() - start
        assert all(ok.all() for ok, _ in decoded)
        start = time.perf_counter()
        for raw in raws:
            messages.multiarray_to_array(TYPESTORE.deserialize_cdr(
                raw, layouts.FLOAT64_MULTIARRAY), expected_length=6, max_length=1024)
        decode_each = time.perf_counter() - start

        def evaluate_all() -> list[stiffness_node.JointOutputs]:
            outputs = []
            for k in range(0, n, chunk):
                out = stiffness_node.joint_outputs_batch(settings.model, screws[k:k + chunk])
                assert stiffness_node.finite_rows(out).all()
                outputs.append(out)
            return outputs

        start = time.perf_counter()
        with bag_topics.single_threaded_blas():
            outputs = evaluate_all()
        library = time.perf_counter() - start
        start = time.perf_counter()
        evaluate_all()
        library_threads = time.perf_counter() - start

        typestore = bag_topics.jazzy_typestore()
        output_layouts = layouts.joint_output_layouts(settings.model.string_names)
        outputs_spec = bag_topics.NODE_TOPICS['stiffness'].outputs
        templates = {name: bag_writers.OutputTemplate(typestore, output_layouts[name],
                                         settings.link1_frame) for name in bag_topics.OUTPUT_NAMES}
        start = time.perf_counter()
        with Writer(Path(tmp) / 'w', version=9,
                    storage_plugin=StoragePlugin[args.storage.upper()]) as writer:
            conns = [writer.add_connection(f'/t/{name}', outputs_spec[name], typestore=typestore)
                     for name in bag_topics.OUTPUT_NAMES]
            for b, out in enumerate(outputs):
                times = np.arange(b * chunk, b * chunk + len(out.screw), dtype=np.int64) + 1
                s = out.state
                payloads = dict(zip(layouts.JOINT_OUTPUTS, (
                    s.wrench, s.stiffness, s.cartesian_stiffness, s.tensions,
                    out.interpretation), strict=True))
                # the stamped matrices: their source's payload
                bag_writers.write_blocks(writer, conns, times, [
                    templates[name].rows(payloads[output_layouts[name].source or name],
                                         times if templates[name].stamped else None)
                    for name in bag_topics.OUTPUT_NAMES])
        write = time.perf_counter() - start

    rate = n / end_to_end
    print(f'end to end         : {rate:9.0f} inputs/s  (best of {args.repeat}: '
          f'{end_to_end:.2f} s for {n}; runs {", ".join(f"{t:.2f}" for t in runs["this"])} s;'
          f' target 20000/s: {"met" if rate >= 20_000 else "NOT met"})')
    if baseline is not None:
        base = min(runs['baseline'])
        print(f'baseline end to end: {n / base:9.0f} inputs/s  (best of {args.repeat}: '
              f'{base:.2f} s; runs {", ".join(f"{t:.2f}" for t in runs["baseline"])} s; '
              f'{args.baseline})')
        print(f'this / baseline    : {base / end_to_end:9.2f} x throughput '
              f'({100 * (base / end_to_end - 1):+.0f} %)')
    parts = (('read (rosbags)', iterate), ('decode in blocks', decode),
             ('library (batched)', library), ('write in blocks', write))
    for name, seconds in parts:
        print(f'{name:<19}: {n / seconds:9.0f} inputs/s  ({1e6 * seconds / n:5.1f} us per '
              f'input, {100 * seconds / end_to_end:3.0f}% of end to end)')
    print('per-message decoding replaced, default BLAS threads (for comparison):')
    for name, seconds in (('decode each', decode_each), ('library, BLAS thr.', library_threads)):
        print(f'{name:<19}: {n / seconds:9.0f} inputs/s  ({1e6 * seconds / n:5.1f} us per '
              f'input)')


if __name__ == '__main__':
    main()
