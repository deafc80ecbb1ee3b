"""The twins' nodes (``sim_node``, ``structure_sim_node``): only the stepping thread touches
the MuJoCo simulation, read from the code.

MuJoCo's data is not safe to use from two threads: a contact force computed beside ``mj_step``
(``mj_forwardSkip`` on the same ``mjData``) crashed ``structure_sim_node`` with SIGSEGV in a CI
run. The executor's callbacks (timers, subscriptions, the parameter callback) and every method
they call may use only the simulation's fixed facts (:data:`FIXED`)."""

from __future__ import annotations

import ast

import pytest
from support import REPO

NODES = ('tensegrity_stiffness/ros/sim_node.py', 'tensegrity_stiffness/ros/structure_sim_node.py')
#: The simulation's attributes fixed at its construction (bounds, names): safe from any thread.
FIXED = frozenset({'validated_rest_lengths', 'imu_bodies', 'marker_names'})
#: The attribute holding the simulation in both nodes.
SIMULATION = '_sim'


def _self_attribute(node: ast.AST) -> str | None:
    """``X`` of an expression ``self.X``, else None."""
    if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
            and node.value.id == 'self'):
        return node.attr
    return None


def _callbacks(cls: ast.ClassDef) -> set[str]:
    """Names of the methods handed to the executor: ``create_timer``'s callback, a
    subscription's or a service's callback, and the parameter binding's apply callback."""
    position = {'create_timer': 1, 'create_subscription': 2, 'create_service': 2}
    names = set()
    for node in ast.walk(cls):
        if not isinstance(node, ast.Call):
            continue
        if isinstance(node.func, ast.Attribute) and node.func.attr in position:
            args = node.args[position[node.func.attr]:position[node.func.attr] + 1]
        elif isinstance(node.func, ast.Name) and node.func.id == 'ParameterBinding':
            args = node.args
        else:
            continue
        names.update(a for a in map(_self_attribute, args) if a)
    return names


def simulation_uses_off_the_stepping_thread(source: str) -> list[str]:
    """``method: self._sim[.attribute]`` for every use of the simulation other than
    :data:`FIXED` in an executor callback or a method it calls (``self.<method>``)."""
    wrong = []
    for cls in (n for n in ast.parse(source).body if isinstance(n, ast.ClassDef)):
        methods = {f.name: f for f in cls.body if isinstance(f, ast.FunctionDef)}
        todo, seen = sorted(_callbacks(cls) & methods.keys()), set()
        while todo:
            name = todo.pop()
            if name in seen:
                continue
            seen.add(name)
            function = methods[name]
            used = {_self_attribute(n) for n in ast.walk(function)}
            todo.extend(sorted((used & methods.keys()) - seen))
            parents = {child: parent for parent in ast.walk(function)
                       for child in ast.iter_child_nodes(parent)}
            for node in ast.walk(function):
                if _self_attribute(node) != SIMULATION:
                    continue
                parent = parents.get(node)
                if isinstance(parent, ast.Attribute) and parent.attr in FIXED:
                    continue
                what = (f'.{parent.attr}' if isinstance(parent, ast.Attribute) else '')
                wrong.append(f'{name}: self.{SIMULATION}{what}')
    return wrong


@pytest.mark.parametrize('path', NODES)
def test_only_the_stepping_thread_touches_the_simulation(path) -> None:
    assert simulation_uses_off_the_stepping_thread((REPO / path).read_text()) == []


def test_a_callback_touching_the_simulation_is_found() -> None:
    source = '''
class Twin:
    def __init__(self):
        self.create_timer(1.0, self._report)
        self.create_subscription(T, 'x', self._on_x, 10)
    def _report(self):
        self._summary()
    def _summary(self):
        sim = self._sim
        return sim.contact_nodes()
    def _on_x(self, msg):
        return self._sim.validated_rest_lengths(msg)
    def _run(self):
        self._sim.step(1)
'''
    assert simulation_uses_off_the_stepping_thread(source) == ['_summary: self._sim']
