"""Structure calibration recordings for the tests: the MuJoCo twin of a structure whose strings'
stiffnesses and rest-length offsets are known, driven through holds of random rest-length
commands, its lengths, load cells and encoders read at a fixed rate as ``structure_sim_node``
publishes them; written as a CSV (the joint's columns) or a rosbag2 of the twin's topics."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from tensegrity_stiffness.recordings.calibration_recording import Recording
from tensegrity_stiffness.recordings.structure_recording import DEFAULT_TOPICS
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import Structure

#: Readings per second, seconds per hold, the motors' speed (m/s, the node's default) and the
#: commands' spread (relative, uniform) around the nominal rest lengths.
RATE = 50.0
HOLD_TIME = 1.5
MOTOR_SPEED = 0.02
SPREAD = 0.03


def perturbed_strings(nominal: Structure, rng: np.random.Generator
                      ) -> tuple[Structure, np.ndarray, np.ndarray]:
    """(the true structure, its stiffnesses, the encoders' offsets), drawn from ``rng``:
    stiffness 10 % off nominal (normal), offsets within +-3 mm."""
    k = nominal.k * (1 + 0.1 * rng.standard_normal(nominal.n_strings))
    offsets = 3e-3 * rng.uniform(-1, 1, nominal.n_strings)
    truth = Structure(nominal.bodies,
                      [dataclasses.replace(s, stiffness=float(v)) for s, v in
                       zip(nominal.strings, k, strict=True)],
                      nominal.world_nodes, nominal.gravity, nominal.ground, nominal.force_law)
    return truth, k, offsets


def twin_series(truth: Structure, offsets: np.ndarray, holds: int, seed: int,
                length_noise: float, tension_noise: float) -> Recording:
    """The twin of ``truth`` through ``holds`` holds: encoders = the rest lengths in force minus
    ``offsets`` (true rest = encoder + offset), lengths and tensions with noise."""
    from tensegrity_stiffness.simulation.structure_twin import (
        StructureSimulation,
        StructureTwinOptions,
        measure_structure,
    )
    from tensegrity_stiffness.simulation.twin import SensorNoise

    rng = np.random.default_rng(seed + 1000)
    sim = StructureSimulation(truth, StructureTwinOptions(rest_length_rate=MOTOR_SPEED),
                              poses=solve_structure_equilibrium(truth).poses)
    noise = SensorNoise(lengths=length_noise, tensions=tension_noise)
    steps = round(1.0 / (RATE * sim.options.timestep))
    n = truth.n_strings
    times, enc, lengths, tensions = [], [], [], []
    for _ in range(holds):
        sim.set_rest_lengths(truth.rest_lengths * (1 + SPREAD * rng.uniform(-1, 1, n)))
        for _ in range(round(HOLD_TIME * RATE)):
            sim.step(steps)
            z = measure_structure(sim, noise, rng)
            times.append(sim.time)
            enc.append(z.encoders - offsets)
            lengths.append(z.lengths)
            tensions.append(z.tensions)
    M = len(times)
    return Recording(np.array(times), np.array(enc), np.full((M, 4, 4), np.nan),
                     np.full((M, 6), np.nan), np.array(tensions), np.array(lengths), 'twin')


def write_bag(path: Path, recording: Recording, storage: str = 'mcap',
              skip: tuple[str, ...] = ()) -> None:
    """``recording`` as a rosbag2 of the twin's topics (:data:`DEFAULT_TOPICS`), each instant's
    lengths, tensions and encoders logged in the order the node publishes them, 1 us apart;
    the signals ``skip`` left out."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    ty = store.types
    kind = 'std_msgs/msg/Float64MultiArray'
    series = {'lengths': recording.lengths, 'tensions': recording.tensions,
              'rest_lengths': recording.rest}
    with Writer(path, version=9, storage_plugin=StoragePlugin[storage.upper()]) as writer:
        conn = {signal: writer.add_connection(DEFAULT_TOPICS[signal], kind, typestore=store)
                for signal in series if signal not in skip}
        for i, t in enumerate(recording.times):
            for order, (signal, values) in enumerate(series.items()):
                if signal in skip:
                    continue
                msg = ty[kind](layout=ty['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0),
                               data=np.asarray(values[i], dtype=np.float64))
                writer.write(conn[signal], round(float(t) * 1e9) + 1000 * order,
                             store.serialize_cdr(msg, kind))
