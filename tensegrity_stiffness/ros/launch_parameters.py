"""Single parameters on the ``ros2 launch`` command line, beside a parameter file, for the
package's launch files (``launch/*.launch.py``)::

    ros2 launch tensegrity_stiffness control.launch.py params_file:=lab_joint.yaml \\
        limits.tension_max:=3.0 control.rate:=200

Every ``name:=value`` that names a parameter of a node's table (docs/parameters.md), or
``use_sim_time``, is set on each node of the launch file whose table has it, after the parameter
file (so it wins), typed and checked by the table: ``3`` for a double is 3.0, and a value of the
wrong type or out of range stops the launch with a ValueError naming the argument.
``ros2 launch`` keeps every ``name:=value`` it is given as a launch configuration, declared or
not (a node's parameters are too many to declare one by one; the launch files declare
``namespace``, ``params_file`` and a few common ones, which ``--show-args`` lists).

:func:`single_parameters` is the rule and imports no ``launch`` (which is not on PyPI: the tests
check the rule and read the launch files); :func:`launch_node` is the action the launch files
use, importing ``launch`` and ``launch_ros`` when called.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import yaml

from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec, by_name
from tensegrity_stiffness.nodes.registry import node_tables

PACKAGE = 'tensegrity_stiffness'
#: The launch argument of the ROS parameter file every launch file takes (empty: none).
PARAMS_FILE = 'params_file'
#: Parameters every rclpy node has beside its table.
ROS_NODE_PARAMETERS = (
    ParameterSpec('use_sim_time', 'bool', False, 'take the time from /clock (a simulator)'),
)


def node_parameters(executable: str) -> tuple[ParameterSpec, ...]:
    """The parameters ``executable`` takes: its table (``node_tables``; a spine's for the default
    number of joints) and :data:`ROS_NODE_PARAMETERS`. ValueError for a name without a table."""
    for table in node_tables():
        if table.node == executable:
            return (*table.parameters, *ROS_NODE_PARAMETERS)
    raise ValueError(f'no parameter table for the executable {executable!r}: one of '
                     f'{", ".join(t.node for t in node_tables())}')


def parse_value(spec: ParameterSpec, text: str) -> Any:
    """The launch argument ``text`` as the value of ``spec``: a string parameter takes the text as
    it is; any other is read as YAML (as ``ros2 run ... -p name:=value``) and checked by the
    table (``ParameterSpec.check``: an int for a double becomes a float). ValueError naming the
    argument."""
    if spec.type == 'string':
        value: Any = text
    else:
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise ValueError(f'launch argument {spec.name}:={text}: not a value '
                             f'({error})') from None
    try:
        return spec.check(value)
    except ValueError as error:
        raise ValueError(f'launch argument {spec.name}:={text}: {error}') from None


def single_parameters(executable: str, configurations: Mapping[str, str]
                      ) -> dict[str, Any]:
    """The parameters of ``executable`` set by launch configurations (``name:=value``, the
    launch context's ``launch_configurations``), typed; the other configurations are not its
    parameters and are left alone."""
    specs = by_name(node_parameters(executable))
    return {name: parse_value(specs[name], str(text))
            for name, text in configurations.items() if name in specs}


def node_parameter_list(executable: str, configurations: Mapping[str, str],
                        fixed: Sequence[Any] = ()) -> list[Any]:
    """The ``parameters`` of a launched ``executable``, lowest precedence first: the parameter
    file (``params_file``, when not empty), the launch file's ``fixed`` entries (dicts, possibly
    of substitutions), then the single parameters of :func:`single_parameters`."""
    entries: list[Any] = []
    if configurations.get(PARAMS_FILE):
        entries.append(configurations[PARAMS_FILE])
    entries += list(fixed)
    given = single_parameters(executable, configurations)
    if given:
        entries.append(given)
    return entries


def launch_node(executable: str, fixed: Sequence[Any] = (), name: str | None = None,
                remappings: Iterable[tuple[str, str]] | Callable[[Any], Iterable[tuple[str, str]]]
                = (), **node_arguments: Any) -> Any:
    """A launch action (``OpaqueFunction``) that starts ``executable`` of this package as a
    ``launch_ros`` ``Node`` named ``name`` (default the executable) with the parameters of
    :func:`node_parameter_list`, ``remappings`` (pairs, or a function of the launch context
    returning them: remappings that depend on a launch argument), output on the screen and
    ``node_arguments`` (``namespace=LaunchConfiguration('namespace')``, ...)."""
    from launch.actions import OpaqueFunction
    from launch_ros.actions import Node

    remap = remappings if callable(remappings) else (lambda _context, r=list(remappings): r)

    def start(context: Any, *args: Any, **kwargs: Any) -> list:
        parameters = node_parameter_list(executable, context.launch_configurations, fixed)
        return [Node(package=PACKAGE, executable=executable, name=name or executable,
                     parameters=parameters, remappings=list(remap(context)), output='screen',
                     emulate_tty=True, **node_arguments)]

    return OpaqueFunction(function=start)
