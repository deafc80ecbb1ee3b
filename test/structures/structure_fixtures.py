"""Shared structures of the structure tests: the 3-prism and the 6-bar of this folder, a
regular p-prism of any p, a mixed structure (a general body, bars, world nodes, limits) and
seeded perturbations of poses."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.structures.structure import Structure, twist_exp

PRISM3 = 'prism3_structure.yaml'
SIXBAR = 'sixbar_structure.yaml'


#: The folder of this file, which holds the example structures.
HERE = Path(__file__).resolve().parent


def example(name: str, **kwargs) -> Structure:
    """An example structure of this folder."""
    return Structure.from_yaml(HERE / name, **kwargs)


def bar_pose(p: np.ndarray, q: np.ndarray) -> list[float]:
    """The pose [x y z qx qy qz qw] of a bar from node a at ``p`` to node b at ``q``."""
    e = (q - p) / np.linalg.norm(q - p)
    helper = np.array([1.0, 0, 0]) if abs(e[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(helper, e)
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(e, x), e])
    return list((p + q) / 2) + list(rotation_to_quaternion(R))


def prism_document(p: int, radius: float = 0.2, height: float = 0.3,
                   twist_deg: float | None = None, ring_ratio: float = 0.9,
                   vertical_ratio: float = 0.9, k: float = 100.0) -> dict:
    """A regular p-prism: bar i from bottom node i to top node i, rings and vertical strings
    (bottom i to top i-1), rest lengths the given ratios of the start lengths."""
    phi = math.radians(90.0 + 180.0 / p if twist_deg is None else twist_deg)
    ang = [2 * math.pi * i / p for i in range(p)]
    bot = [np.array([radius * math.cos(t), radius * math.sin(t), 0.0]) for t in ang]
    top = [np.array([radius * math.cos(t + phi), radius * math.sin(t + phi), height])
           for t in ang]
    bodies = [{'name': f'bar{i}', 'type': 'bar', 'length': float(np.linalg.norm(top[i] - bot[i])),
               'pose': bar_pose(bot[i], top[i]), 'mass': 0.05} for i in range(p)]
    strings = []
    for i in range(p):
        j, m = (i + 1) % p, (i - 1) % p
        strings += [
            {'name': f'bottom{i}', 'from': f'bar{i}.a', 'to': f'bar{j}.a', 'stiffness': k,
             'rest_length': ring_ratio * float(np.linalg.norm(bot[i] - bot[j]))},
            {'name': f'top{i}', 'from': f'bar{i}.b', 'to': f'bar{j}.b', 'stiffness': k,
             'rest_length': ring_ratio * float(np.linalg.norm(top[i] - top[j]))},
            {'name': f'vertical{i}', 'from': f'bar{i}.a', 'to': f'bar{m}.b', 'stiffness': k,
             'rest_length': vertical_ratio * float(np.linalg.norm(bot[i] - top[m]))}]
    return {'structure': {'bodies': bodies, 'strings': strings}}


def mixed_document(force_law: str = 'hooke') -> dict:
    """A general body, two bars and world anchors, with string limits (some saturated)."""
    return {'structure': {
        'force_law': force_law,
        'gravity': [0.0, 0.0, -9.81],
        'bodies': [
            {'name': 'hub', 'type': 'body', 'nodes': {'A': [0.05, 0, 0], 'B': [-0.03, 0.04, 0],
                                                      'C': [0, -0.04, 0.03]},
             'pose': [0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 1.0], 'mass': 0.2, 'com': [0.01, 0, 0]},
            {'name': 'bar0', 'type': 'bar', 'length': 0.3,
             'pose': [0.1, 0.05, 0.25, 0.1, 0.2, 0.0, math.sqrt(0.95)], 'mass': 0.05},
            {'name': 'bar1', 'type': 'bar', 'length': 0.25,
             'pose': [-0.1, 0.0, 0.15, 0.0, 0.6, 0.0, 0.8], 'mass': 0.05}],
        'world_nodes': {'w0': [0.2, 0.0, 0.5], 'w1': [-0.2, 0.1, 0.5]},
        'strings': [
            {'from': 'hub.A', 'to': 'bar0.a', 'stiffness': 80.0, 'rest_length': 0.05},
            {'from': 'hub.B', 'to': 'bar1.b', 'stiffness': 60.0, 'rest_length': 0.08,
             'max_length': 0.1},
            {'from': 'hub.C', 'to': 'bar1.a', 'stiffness': 70.0, 'rest_length': 0.06},
            {'from': 'bar0.b', 'to': 'world.w0', 'stiffness': 90.0, 'rest_length': 0.1},
            {'from': 'world.w1', 'to': 'bar1.b', 'stiffness': 50.0, 'rest_length': 0.2},
            {'from': 'bar0.a', 'to': 'bar1.a', 'stiffness': 40.0, 'rest_length': 0.5},  # slack
            {'from': 'hub.A', 'to': 'world.w0', 'stiffness': 30.0, 'rest_length': 0.1,
             'max_length': 0.2}]}}


def perturbed(T: np.ndarray, rng: np.random.Generator, scale: float = 0.02) -> np.ndarray:
    """Each pose moved by a random twist of size ``scale`` (m and rad)."""
    return np.array([twist_exp(rng.normal(scale=scale, size=6)) @ P for P in T])
