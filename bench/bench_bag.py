#!/usr/bin/env python3
"""Throughput of ``tensegrity-stiffness bag``, run by hand: ``python3 bench/bench_bag.py [--n N]``.

Writes an mcap rosbag2 of N screws (default 100,000, 1 kHz log times, near the default joint's
unloaded equilibrium) to a temporary folder, then measures side by side in one run:
* end to end: :func:`tensegrity_stiffness.bag.process_bag` (read, decode and validate as the
  node does, batched evaluation, write five outputs per input), in inputs per second;
* its parts, with the command's own pieces: reading and decoding (rosbags ``Reader.messages``,
  plain screws decoded in blocks with ``plain_screw_values`` and checked with
  ``processing.screw_inputs``); the library (``processing.joint_outputs_batch`` and
  ``finite_rows`` in the command's chunks, OpenBLAS on one thread as in the command);
  writing (the output templates' rows and the block writer, five messages per input); each
  part timed on its own (on a loaded machine they need not add up to the end-to-end time);
* for comparison, the per-message paths they replace (``deserialize_cdr`` +
  ``msg_tools.multiarray_to_array`` per message, five ``Writer.write`` per input), and the
  library with OpenBLAS's default thread count.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))

from test_bag import TYPESTORE, In, multiarray, screw_stream, write_bag  # noqa: E402

import msg_tools  # noqa: E402
from tensegrity_stiffness import bag, layouts, processing  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--n', type=int, default=100_000, help='screws in the bag')
    args = parser.parse_args()
    n, chunk = args.n, bag.CHUNK_SIZE
    screws = screw_stream(n, seed=0)
    settings = bag.node_settings()
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / 'in'
        start = time.perf_counter()
        write_bag(src, [In('screw', 1_000_000 * (i + 1), multiarray(xi))
                        for i, xi in enumerate(screws)])
        print(f'wrote {n} screws in {time.perf_counter() - start:.1f} s')

        start = time.perf_counter()
        summary = bag.process_bag(src, Path(tmp) / 'out')
        end_to_end = time.perf_counter() - start
        assert summary.answers == n, summary

        start = time.perf_counter()
        with Reader(src) as reader:
            raws = [raw for _, _, raw in reader.messages()]
        iterate = time.perf_counter() - start
        start = time.perf_counter()
        decoded = [processing.screw_inputs(bag.plain_screw_values(raws[k:k + chunk]))
                   for k in range(0, n, chunk)]
        decode = time.perf_counter() - start
        assert all(ok.all() for ok, _ in decoded)
        start = time.perf_counter()
        for raw in raws:
            msg_tools.multiarray_to_array(TYPESTORE.deserialize_cdr(
                raw, bag.FLOAT64_MULTIARRAY), expected_length=6, max_length=1024)
        decode_each = time.perf_counter() - start

        def evaluate_all() -> list[processing.JointOutputs]:
            outputs = []
            for k in range(0, n, chunk):
                out = processing.joint_outputs_batch(settings.model, screws[k:k + chunk])
                assert processing.finite_rows(out).all()
                outputs.append(out)
            return outputs

        start = time.perf_counter()
        with bag.single_threaded_blas():
            outputs = evaluate_all()
        library = time.perf_counter() - start
        start = time.perf_counter()
        evaluate_all()
        library_threads = time.perf_counter() - start

        typestore = bag._typestore()
        messages = bag.output_messages(typestore, settings.model.string_names,
                                       settings.link1_frame)
        sizes = {'wrench': 6, 'stiffness': 36, 'cartesian_stiffness': 36,
                 'string_tensions': settings.model.n_strings,
                 'stiffness_interpretation': layouts.INTERPRETATION_SIZE}
        outputs_spec = bag.NODE_TOPICS['stiffness'].outputs
        templates = {name: bag._Template(typestore, outputs_spec[name], messages[name],
                                         sizes[name], name == 'wrench')
                     for name in bag.OUTPUT_NAMES}
        start = time.perf_counter()
        with Writer(Path(tmp) / 'w', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = [writer.add_connection(f'/t/{name}', outputs_spec[name],
                                           typestore=typestore) for name in bag.OUTPUT_NAMES]
            block_writer = bag._BlockWriter(writer)
            for b, out in enumerate(outputs):
                times = np.arange(b * chunk, b * chunk + len(out.screw), dtype=np.int64) + 1
                s = out.state
                payloads = (s.wrench, s.stiffness, s.cartesian_stiffness, s.tensions,
                            out.interpretation)
                block_writer.write(conns, times, [
                    templates[name].rows(p, times if name == 'wrench' else None)
                    for name, p in zip(bag.OUTPUT_NAMES, payloads, strict=True)])
        write = time.perf_counter() - start

        payload = bytes(372)
        m = min(n, 20_000)
        start = time.perf_counter()
        with Writer(Path(tmp) / 'w1', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = [writer.add_connection(f'/t{i}', bag.FLOAT64_MULTIARRAY,
                                           typestore=TYPESTORE) for i in range(5)]
            for i in range(m):
                for c in conns:
                    writer.write(c, i, payload)
        write_each = (time.perf_counter() - start) * n / m

    rate = n / end_to_end
    print(f'end to end         : {rate:9.0f} inputs/s  ({end_to_end:.2f} s for {n}; target '
          f'20000/s: {"met" if rate >= 20_000 else "NOT met"})')
    parts = (('read (rosbags)', iterate), ('decode in blocks', decode),
             ('library (batched)', library), ('write in blocks', write))
    for name, seconds in parts:
        print(f'{name:<19}: {n / seconds:9.0f} inputs/s  ({1e6 * seconds / n:5.1f} us per '
              f'input, {100 * seconds / end_to_end:3.0f}% of end to end)')
    print('per-message paths replaced, default BLAS threads (for comparison):')
    for name, seconds in (('decode each', decode_each), ('5 writes each', write_each),
                          ('library, BLAS thr.', library_threads)):
        print(f'{name:<19}: {n / seconds:9.0f} inputs/s  ({1e6 * seconds / n:5.1f} us per '
              f'input)')


if __name__ == '__main__':
    main()
