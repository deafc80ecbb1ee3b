#!/usr/bin/env python3
"""Throughput of ``tensegrity-stiffness bag``, run by hand: ``python3 bench/bench_bag.py [--n N]``.

Writes an mcap rosbag2 of N screws (default 100,000, 1 kHz log times, near the default joint's
unloaded equilibrium) to a temporary folder, then measures side by side in one run:
* end to end: :func:`tensegrity_stiffness.bag.process_bag` (read, decode and validate as the
  node does, batched evaluation, write five outputs per input), in inputs per second;
* the library part alone: ``JointModel.evaluate`` on the same screws in the command's chunks plus
  ``interpretation_vector`` per answer;
* reading and decoding alone (rosbags ``messages`` + ``deserialize_cdr`` +
  ``msg_tools.multiarray_to_array``), and writing alone (five ``Writer.write`` per input).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))

from test_bag import TYPESTORE, In, multiarray, screw_stream, write_bag  # noqa: E402

import msg_tools  # noqa: E402
from tensegrity_stiffness import bag, config  # noqa: E402
from tensegrity_stiffness.interpretation import interpretation_vector  # noqa: E402
from tensegrity_stiffness.joint import JointModel  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--n', type=int, default=100_000, help='screws in the bag')
    args = parser.parse_args()
    screws = screw_stream(args.n, seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / 'in'
        start = time.perf_counter()
        write_bag(src, [In('screw', 1_000_000 * (i + 1), multiarray(xi))
                        for i, xi in enumerate(screws)])
        print(f'wrote {args.n} screws in {time.perf_counter() - start:.1f} s')

        start = time.perf_counter()
        summary = bag.process_bag(src, Path(tmp) / 'out')
        end_to_end = time.perf_counter() - start
        assert summary.answers == args.n, summary

        from rosbags.rosbag2 import Reader

        start = time.perf_counter()
        with Reader(src) as reader:
            for _, _, raw in reader.messages():
                msg_tools.multiarray_to_array(TYPESTORE.deserialize_cdr(
                    raw, bag.FLOAT64_MULTIARRAY), expected_length=6, max_length=1024)
        read = time.perf_counter() - start

        model = JointModel.from_yaml(config.packaged_config_path())
        start = time.perf_counter()
        for k in range(0, args.n, bag.CHUNK_SIZE):
            state = model.evaluate(screws[k:k + bag.CHUNK_SIZE])
        evaluate = time.perf_counter() - start
        start = time.perf_counter()
        for K in model.evaluate(screws).stiffness:
            interpretation_vector(K)
        interpret = time.perf_counter() - start
        del state

        from rosbags.rosbag2 import StoragePlugin, Writer

        payload = bytes(372)
        start = time.perf_counter()
        with Writer(Path(tmp) / 'w', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = [writer.add_connection(f'/t{i}', bag.FLOAT64_MULTIARRAY,
                                           typestore=TYPESTORE) for i in range(5)]
            for i in range(args.n):
                for c in conns:
                    writer.write(c, i, payload)
        write = time.perf_counter() - start

    rate = args.n / end_to_end
    print(f'end to end     : {rate:10.0f} inputs/s  ({end_to_end:.2f} s for {args.n}; target '
          f'20000/s: {"met" if rate >= 20_000 else "NOT met"})')
    for name, seconds in (('read + decode', read), ('JointModel.evaluate', evaluate),
                          ('interpretation', interpret), ('5 writes/input', write),
                          ('library (eval+interp)', evaluate + interpret)):
        print(f'{name:<15}: {args.n / seconds:10.0f} inputs/s  ({1e6 * seconds / args.n:6.1f} '
              f'us per input, {100 * seconds / end_to_end:4.0f}% of end to end)')


if __name__ == '__main__':
    main()
