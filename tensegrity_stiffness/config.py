"""Reading configurations: plain YAML files and ROS 2 parameter files, one reader for the
library, the nodes, the command line and the tests.

A ROS parameter file has the node's parameters under ``<node name>: ros__parameters:`` (the
packaged ``config/default_joint.yaml`` uses ``/**``, any node); a plain config has the same
sections (``joint``, ``planar``, ...) at the top level. :func:`parameters` returns that mapping for
either form, :func:`section` one section of it.

No ROS import: the packaged files are found through ``AMENT_PREFIX_PATH`` (as the ament index
does), under the Python prefix (``pip install .``) or next to the source tree.
"""

from __future__ import annotations

import difflib
import os
import sys
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

PACKAGE = 'tensegrity_stiffness'
#: The packaged configuration of the joint node (the default joint, frames, planar mechanism).
DEFAULT_JOINT_CONFIG = 'default_joint.yaml'
#: Folder of config/ with the worked examples of docs/your_joint.md.
EXAMPLES = 'examples'
#: Key under which a ROS parameter file holds a node's parameters.
ROS_PARAMETERS = 'ros__parameters'
#: The largest config file a reader takes, bytes: a 100-string joint or a 100-joint spine is
#: well under 100 kB, so a larger file is a mistake (and would take unbounded time to read).
MAX_CONFIG_BYTES = 1 << 20


class UnknownKeyWarning(UserWarning):
    """A key of a config section that no reader knows, read with ``strict=False`` (a file
    shared with other tools): the key is ignored."""


def packaged_path(relative: str) -> Path:
    """``<relative>`` (e.g. ``rviz/tensegrity.rviz``) of the installed package's share folder
    (``<prefix>/share/tensegrity_stiffness`` of the first ``AMENT_PREFIX_PATH`` entry that has
    it, then of the Python prefix of a ``pip install``), else of the source tree."""
    prefixes = os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) + [sys.prefix]
    for prefix in filter(None, prefixes):
        path = Path(prefix) / 'share' / PACKAGE / relative
        if path.is_file():
            return path
    return Path(__file__).resolve().parents[1] / relative


def packaged_config_path(name: str = DEFAULT_JOINT_CONFIG) -> Path:
    """``config/<name>`` of the installed package, else of the source tree
    (:func:`packaged_path`)."""
    return packaged_path(f'config/{name}')


def example_config_path(name: str) -> Path:
    """``config/examples/<name>`` of the installed package (:func:`packaged_config_path`): the
    worked examples of docs/your_joint.md. ValueError names a missing example."""
    path = packaged_config_path(f'{EXAMPLES}/{name}')
    if not path.is_file():
        raise ValueError(f'no packaged example {name!r} (config/{EXAMPLES}: '
                         f'{", ".join(sorted(p.name for p in path.parent.glob("*.yaml")))})')
    return path


def load_yaml(path: str | Path) -> Any:
    """Read a YAML file (PyYAML), with a clear error for a missing, malformed, too large
    (:data:`MAX_CONFIG_BYTES`) or too deeply nested file."""
    import yaml

    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_CONFIG_BYTES:
            raise ValueError(f'config {path} has {size} bytes, more than the {MAX_CONFIG_BYTES} '
                             'a config may have (MAX_CONFIG_BYTES)')
        with path.open(encoding='utf-8') as handle:
            return yaml.safe_load(handle)
    except OSError as exc:
        raise ValueError(f'cannot read config {path}: {exc.strerror}') from None
    except UnicodeDecodeError as exc:
        raise ValueError(f'config {path} is not UTF-8 text: {exc.reason} at byte '
                         f'{exc.start}') from None
    except RecursionError:
        raise ValueError(f'config {path} is nested too deeply to read') from None
    except yaml.YAMLError as exc:
        raise ValueError(f'config {path} is not valid YAML: {exc}') from None


def unknown_key_messages(mapping: Mapping[str, Any], known: Iterable[str], where: str
                         ) -> list[str]:
    """One message per key of ``mapping`` (the section ``where``) that is not in ``known``:
    ``joint.stifness: unknown key (did you mean joint.stiffness?)``: the one format of every
    reader (library, command line, bag, nodes)."""
    known = list(known)
    lines = []
    for key in mapping:
        if key in known:
            continue
        close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
        hint = f' (did you mean {where}.{close[0]}?)' if close else ''
        lines.append(f'{where}.{key}: unknown key{hint}')
    return lines


def check_keys(mapping: Mapping[str, Any], known: Iterable[str], where: str,
               strict: bool = True) -> None:
    """Refuse (ValueError) the unknown keys of ``mapping`` (:func:`unknown_key_messages`), or,
    with ``strict=False`` (a file shared with other tools), warn (:class:`UnknownKeyWarning`)
    and go on."""
    lines = unknown_key_messages(mapping, known, where)
    if not lines:
        return
    if strict:
        raise ValueError('; '.join(lines))
    for line in lines:
        warnings.warn(f'{line}: ignored', UnknownKeyWarning, stacklevel=3)


def write_yaml(path: str | Path, document: Any, header: list[str] | tuple[str, ...] = ()
               ) -> Path:
    """Write a config document as YAML (block mappings, flow lists, keys in order) after the
    ``header`` lines as ``#`` comments; ValueError when the folder does not exist."""
    path = Path(path)
    if not path.parent.is_dir():
        raise ValueError(f'output folder {path.parent} does not exist')
    path.write_text(yaml_text(document, header), encoding='utf-8')
    return path


def yaml_text(document: Any, header: list[str] | tuple[str, ...] = ()) -> str:
    """The text :func:`write_yaml` writes."""
    import yaml

    comments = ''.join(f'# {line}\n' if line else '#\n' for line in header)
    return comments + yaml.safe_dump(document, default_flow_style=None, sort_keys=False,
                                     width=99)


def parameters(document: Any) -> Mapping[str, Any]:
    """The parameter mapping of a config document: the ``ros__parameters`` of the first node
    entry of a ROS parameter file, else the document itself (a plain config)."""
    if not isinstance(document, Mapping):
        raise ValueError('config must be a YAML mapping')
    for value in document.values():
        if isinstance(value, Mapping) and isinstance(value.get(ROS_PARAMETERS), Mapping):
            return value[ROS_PARAMETERS]
    return document


def section(document: Any, key: str, required: bool = True) -> Mapping[str, Any]:
    """``parameters(document)[key]``; ValueError naming ``key`` when it is missing and
    ``required`` (else an empty mapping)."""
    value = parameters(document).get(key)
    if isinstance(value, Mapping):
        return value
    if value is None and not required:
        return {}
    raise ValueError(f'config has no "{key}" section (top level or under {ROS_PARAMETERS})')


def load_section(path: str | Path, key: str, required: bool = True) -> Mapping[str, Any]:
    """:func:`section` of the YAML file at ``path``."""
    return section(load_yaml(path), key, required)
