#!/usr/bin/env python3
"""How soon a ``stiffness_bridge`` that runs before its controller delivers its first update
(issue 37, item 7), with what happened on both sides, before and after
``target.first_contact_timeout``. Run by hand after ``source scripts/env.sh``:

    python bench/bench_bridge_first_update.py [--runs 20] [--load 2] [--crowd 8] [--timeout 3]
        [--modes before,after] [--raw events.jsonl]

Each run starts a bridge (``cartesian_controllers`` preset, its defaults but for the mode's
``target.first_contact_timeout`` and ``--timeout``), streams K_c to it at 100 Hz, waits 1 s,
then starts the controller stand-in (``test/support/controller_standins.py``, Fast DDS defaults,
as a C++ controller). Instrumented from outside the package: the bridge's process wraps rclpy's
public ``Client`` (the time ``service_is_ready()`` first turns true, each call sent, answered,
given up on); the controller's process adds a set-parameters callback (each request's arrival),
watches its own graph for the bridge's request writer and response reader (its discovery of
them), times its executor, and keeps rclpy's ``failed to send response (timeout)`` lines (an
answer dropped: the bridge's response reader not matched within 100 ms). Modes alternate run by
run under the same load: ``before`` sets ``target.first_contact_timeout`` 0 (every call waits
``target.timeout``), ``after`` keeps the default. ``--load N``: N busy loops at normal priority;
``--crowd N``: N idle bridge/controller pairs in the domain (as the test file's earlier tests
leave). Prints one line a run and, per mode, the time from the controller ready to the bridge's
first answered call (median, max, count over 2.5 s), and the same from the controller having
discovered the bridge's endpoints (the part the bridge's calls decide). ``uptime`` first and last.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STANDINS = ROOT / 'test' / 'support' / 'controller_standins.py'
CONTROLLER = 'cartesian_compliance_controller'
#: ``target.first_contact_timeout`` of each mode (None: the bridge's default).
MODES = {'before': 0.0, 'after': None, 'default': None}
SLOW_S = 2.5


def bridge_process(argv: list[str]) -> None:
    """The bridge, with rclpy's client calls timed (printed on stdout as ``event t``)."""
    from rclpy.client import Client

    def say(what: str, extra: str = '') -> None:
        print(f'{what} {time.time():.6f} {extra}'.rstrip(), flush=True)

    ready_before = Client.service_is_ready
    call_before = Client.call_async
    remove_before = Client.remove_pending_request
    seen = {'ready': False}

    def service_is_ready(self: Client) -> bool:
        ready = ready_before(self)
        if ready and not seen['ready']:
            seen['ready'] = True
            say('ready')
        return ready

    def call_async(self: Client, request: object) -> object:
        future = call_before(self, request)
        say('call', str(id(future)))
        future.add_done_callback(lambda f: say('answer', str(id(f))))
        return future

    def remove_pending_request(self: Client, future: object) -> None:
        if not future.done():  # rclpy removes answered ones too
            say('given_up', str(id(future)))
        remove_before(self, future)

    Client.service_is_ready = service_is_ready
    Client.call_async = call_async
    Client.remove_pending_request = remove_pending_request
    from tensegrity_stiffness.ros.stiffness_bridge import main

    main(argv)


def controller_process(argv: list[str]) -> None:
    """The stand-in controller, printing its ready time and each request's arrival."""
    sys.path.insert(0, str(STANDINS.parent))
    import controller_standins
    import rclpy
    from rcl_interfaces.msg import SetParametersResult

    rclpy.init(args=argv)
    node = controller_standins.make_node('cartesian_controllers')
    print(f'controller_ready {time.time():.6f}', flush=True)

    def arrived(parameters: list) -> SetParametersResult:
        if parameters and parameters[0].name == 'stiffness.trans_x':
            print(f'request {time.time():.6f}', flush=True)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(arrived)
    service = node.resolve_service_name('~/set_parameters')
    endpoints = {'request_writer': (node.get_publishers_info_by_topic, f'rq{service}Request'),
                 'response_reader': (node.get_subscriptions_info_by_topic, f'rr{service}Reply')}

    def watch_graph() -> None:
        # when this process's graph first shows the bridge's request writer and response
        # reader (its discovery of them; matching happens in the same step)
        left = dict(endpoints)
        while left and rclpy.ok():
            for name, (query, topic) in list(left.items()):
                if query(topic, no_mangle=True):
                    print(f'{name} {time.time():.6f}', flush=True)
                    del left[name]
            time.sleep(0.005)

    threading.Thread(target=watch_graph, daemon=True).start()
    beat = {'last': 0.0}

    def alive() -> None:  # the executor's pace: a gap means it could not have served a request
        now = time.time()
        if beat['last'] == 0.0:
            print(f'spinning {now:.6f}', flush=True)
        elif now - beat['last'] > 0.25:
            print(f'gap {beat["last"]:.6f} {now - beat["last"]:.3f}', flush=True)
        beat['last'] = now

    node.create_timer(0.05, alive)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def events(text: str) -> list[tuple[str, float]]:
    """``(event, time)`` pairs of a process's instrumented output."""
    out = []
    for line in text.splitlines():
        parts = line.split()
        if len(parts) >= 2 and re.fullmatch(r'\d+\.\d+', parts[1]):
            out.append((parts[0], float(parts[1])))
    return out


def start_bridge(namespace: str, first_contact: float | None, tmp: Path,
                 timeout: float | None = None) -> subprocess.Popen:
    params = {'preset': "'cartesian_controllers'",
              'target.node': f"'{namespace}/{CONTROLLER}'"}
    if timeout is not None:
        params['target.timeout'] = repr(timeout)
    if first_contact is not None:
        params['target.first_contact_timeout'] = repr(first_contact)
    body = '\n'.join(f'    {k}: {v}' for k, v in params.items())
    path = tmp / f'{namespace.strip("/")}.yaml'
    path.write_text(f'/**:\n  ros__parameters:\n{body}\n')
    return subprocess.Popen(
        [sys.executable, __file__, '--bridge', '--ros-args', '-r', f'__ns:={namespace}',
         '-r', f'~/input_stiffness:={namespace}/input', '--params-file', str(path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def start_controller(namespace: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, __file__, '--controller', '--ros-args', '-r',
                             f'__ns:={namespace}'],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, 'PYTHONWARNINGS': 'always::RuntimeWarning'})


class Stream:
    """K_c at 100 Hz to one bridge (1 % apart: every input outside the deadband)."""

    def __init__(self, node, topic: str) -> None:
        from std_msgs.msg import Float64MultiArray

        self._type = Float64MultiArray
        self.publisher = node.create_publisher(Float64MultiArray, topic, 10)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        base = [1000.0, 1200.0, 1400.0, 50.0, 60.0, 70.0]
        k = 0
        while not self._stop.is_set():
            f = 1.0 + 0.01 * (k % 200)
            data = [0.0] * 36
            for i, v in enumerate(base):
                data[7 * i] = v * f
            self.publisher.publish(self._type(data=data))
            k += 1
            time.sleep(0.01)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


def run_once(node, mode: str, tmp: Path, timeout: float | None) -> dict:
    namespace = f'/h37_{uuid.uuid4().hex[:8]}'
    bridge = start_bridge(namespace, MODES[mode], tmp, timeout)
    stream = Stream(node, f'{namespace}/input')
    deadline = time.monotonic() + 30.0
    while stream.publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(1.0)
    controller = start_controller(namespace)
    deadline = time.monotonic() + 15.0
    lines: list[str] = []
    b_lines: list[str] = []

    def read(process: subprocess.Popen, into: list[str]) -> None:
        for line in process.stdout:
            into.append(line)

    readers = [threading.Thread(target=read, args=(p, into), daemon=True)
               for p, into in ((controller, lines), (bridge, b_lines))]
    for reader in readers:
        reader.start()
    # until the bridge's first answer (and a few more), or 15 s
    while (sum(line.startswith('answer') for line in b_lines) < 3
           and time.monotonic() < deadline):
        time.sleep(0.05)
    stream.close()
    node.destroy_publisher(stream.publisher)
    for process in (bridge, controller):
        process.send_signal(2)
    for process in (bridge, controller):
        try:
            process.wait(20)
        except subprocess.TimeoutExpired:
            process.kill()
    for reader in readers:
        reader.join(5)
    b_out, b_err = ''.join(b_lines), bridge.stderr.read()
    c_err = controller.stderr.read()
    b = events(b_out)
    c = events(''.join(lines))
    t0 = next((t for e, t in c if e == 'controller_ready'), float('nan'))

    def rel(t: float) -> float:
        return t - t0
    calls = [rel(t) for e, t in b if e == 'call']
    return {
        'mode': mode,
        'first_update': next((rel(t) for e, t in b if e == 'answer'), float('nan')),
        'first_applied': next((rel(t) for e, t in c if e == 'request'), float('nan')),
        'ready': next((rel(t) for e, t in b if e == 'ready'), float('nan')),
        'calls': calls,
        'answers': [rel(t) for e, t in b if e == 'answer'],
        'given_up': [rel(t) for e, t in b if e == 'given_up'],
        'requests': [rel(t) for e, t in c if e == 'request'][:4],
        'spinning': next((rel(t) for e, t in c if e == 'spinning'), float('nan')),
        'request_writer': next((rel(t) for e, t in c if e == 'request_writer'), float('nan')),
        'response_reader': next((rel(t) for e, t in c if e == 'response_reader'),
                                float('nan')),
        'gaps': [(rel(t), float(line.split()[2])) for line in lines
                 if line.startswith('gap') for t in [float(line.split()[1])]],
        'dropped_responses': c_err.count('failed to send response'),
        'bridge_log': b_err,
        'controller_log': c_err,
        'bridge_events': b,
        'controller_events': c,
    }


def udp_receive_buffer_errors() -> int:
    """This machine's count of UDP datagrams dropped for a full socket receive buffer."""
    try:
        rows = [line.split() for line in Path('/proc/net/snmp').read_text().splitlines()
                if line.startswith('Udp:')]
        return int(rows[1][rows[0].index('RcvbufErrors')])
    except (OSError, ValueError, IndexError):
        return -1


def crowd(count: int, tmp: Path) -> list[subprocess.Popen]:
    """``count`` idle bridge/controller pairs in the domain."""
    processes = []
    for _ in range(count):
        namespace = f'/h37_crowd_{uuid.uuid4().hex[:6]}'
        processes.append(start_controller(namespace))
        processes.append(start_bridge(namespace, None, tmp))
    return processes


def given_up(call: float, r: dict) -> bool:
    """Whether the bridge gave up on the call sent at ``call`` (before its next call)."""
    later = [t for t in r['calls'] if t > call]
    end = later[0] if later else float('inf')
    return any(call < g <= end for g in r['given_up'])


def wait_after_discovery(r: dict) -> float:
    """Seconds from the controller seeing both of the bridge's service endpoints (and
    spinning) to the bridge's first answer: the part of the wait the bridge's retries decide.
    NaN when the controller's graph watch missed one (it saw it before the watch began)."""
    seen = max(r['request_writer'], r['response_reader'], r['spinning'])
    return max(0.0, r['first_update'] - seen) if seen == seen else float('nan')


def summary(values: list[float], missing: str = 'none in 15 s') -> str:
    finite = [v for v in values if v == v]
    if not finite:
        return 'no update'
    return (f'median {statistics.median(finite):.2f} s, max {max(finite):.2f} s, over '
            f'{SLOW_S:g} s {sum(v > SLOW_S for v in finite)} of {len(finite)}'
            + (f', {missing} {len(values) - len(finite)}' if len(finite) < len(values)
               else ''))


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] in ('--bridge', '--controller'):
        role = sys.argv.pop(1)
        (bridge_process if role == '--bridge' else controller_process)(sys.argv)
        return
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=20, help='runs per mode')
    parser.add_argument('--load', type=int, default=0, help='busy loops beside the runs')
    parser.add_argument('--crowd', type=int, default=0, help='idle bridge/controller pairs')
    parser.add_argument('--modes', default='before,after')
    parser.add_argument('--timeout', type=float, help='the bridges\' target.timeout (s; '
                        'default: the bridge\'s, 1 s; the across-process test sets 3)')
    parser.add_argument('--raw', type=Path, help='write every run\'s events here (JSON lines)')
    args = parser.parse_args()
    modes = args.modes.split(',')
    import rclpy

    print(subprocess.run(['uptime'], capture_output=True, text=True, check=False).stdout.strip())
    tmp = Path(tempfile.mkdtemp(prefix='h37_'))
    load = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
            for _ in range(args.load)]
    company = crowd(args.crowd, tmp)
    rclpy.init()
    node = rclpy.create_node(f'bench_first_update_{os.getpid()}')
    results: dict[str, list[float]] = {m: [] for m in modes}
    excess: dict[str, list[float]] = {m: [] for m in modes}
    print('run mode    first answer  service ready  calls (s after the controller ready; '
          '*: given up)  requests arrived  responses dropped | controller: spinning, saw '
          'request writer, saw response reader, executor gaps | UDP datagrams dropped (full '
          'receive buffers, whole machine)')
    try:
        time.sleep(3.0 if company else 0.0)
        for k in range(args.runs):
            for mode in modes:
                drops = udp_receive_buffer_errors()
                r = run_once(node, mode, tmp, args.timeout)
                r['udp_drops'] = udp_receive_buffer_errors() - drops
                results[mode].append(r['first_update'])
                excess[mode].append(wait_after_discovery(r))
                if args.raw:
                    with args.raw.open('a') as f:
                        f.write(json.dumps(r) + '\n')
                calls = ' '.join(f'{t:.2f}' + ('*' if given_up(t, r) else '')
                                 for t in r['calls'][:4])
                print(f'{k + 1:3d} {mode:6s} {r["first_update"]:11.2f}  {r["ready"]:12.2f}  '
                      f'{calls:45s}  {" ".join(f"{t:.2f}" for t in r["requests"]):16s}  '
                      f'{r["dropped_responses"]} | {r["spinning"]:.2f} {r["request_writer"]:.2f} '
                      f'{r["response_reader"]:.2f} '
                      + ' '.join(f'{t:.2f}+{d:.2f}' for t, d in r['gaps'] if t < 5.0)
                      + f' | {r["udp_drops"]}',
                      flush=True)
    finally:
        for p in company + load:
            p.send_signal(2) if p in company else p.kill()
        for p in company + load:
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
        node.destroy_node()
        rclpy.try_shutdown()
    print(subprocess.run(['uptime'], capture_output=True, text=True, check=False).stdout.strip())
    print(f'time from the controller ready to its first update (over {SLOW_S:g} s counted):')
    for mode in modes:
        print(f'  {mode:6s}: {summary(results[mode])}')
    print('time from the controller having discovered the bridge (its graph shows the bridge\'s '
          'request writer and response reader) to the first update:')
    for mode in modes:
        print(f'  {mode:6s}: {summary(excess[mode], "not measured")}')


if __name__ == '__main__':
    main()
