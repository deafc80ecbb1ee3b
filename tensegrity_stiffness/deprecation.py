"""The deprecated import paths of the old flat layout, kept working with a warning that names the
path to use (docs/architecture.md, "Documented import paths").

Two kinds: the top-level modules (``tensegrity_stiffness.joint`` ...), each one line that makes
its name the moved module itself (:func:`replace_module`), and the names the subpackages
``estimation``, ``simulation`` and ``control`` used to re-export by star import, now looked up on
first use by the package's ``__getattr__`` (:class:`MovedNames`), so that importing the subpackage
imports none of its modules. Both raise a :class:`DeprecationWarning` whose message starts with
``<old path> is deprecated: use <new path>`` (the test configuration turns exactly these into
errors, so nothing of the package, its tests, benches or examples uses an old path).

Imports nothing of the package: any layer may use it.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import warnings
from collections.abc import Mapping, Sequence
from types import ModuleType

#: The start of every deprecation message of this module (``MESSAGE.format(old=..., new=...)``);
#: setup.cfg's ``filterwarnings`` matches it.
MESSAGE = '{old} is deprecated: use {new}'


def deprecated(old: str, new: str, stacklevel: int) -> None:
    """Warn that the import path ``old`` is deprecated in favour of ``new``, at the frame
    ``stacklevel`` counted as :func:`warnings.warn` does, from the caller of this function (1)."""
    warnings.warn(MESSAGE.format(old=old, new=new), DeprecationWarning, stacklevel=stacklevel + 1)


def replace_module(alias: str, moved: ModuleType) -> None:
    """Make the module name ``alias`` (a top-level module's ``__name__``) the module ``moved``
    itself, after a :class:`DeprecationWarning` naming ``moved``'s path.

    Called from the alias module's body, once per process (later imports find ``moved`` in
    ``sys.modules``): ``from tensegrity_stiffness.joint import JointModel`` and
    ``tensegrity_stiffness.mechanics.joint.JointModel`` stay the same class, and patching one
    patches the other. The warning points at the importing line (the import system's own frames
    are skipped by :mod:`warnings`); when it is made an error the import fails every time.
    """
    # this function (1), the alias module's body (2), the importer (3)
    deprecated(alias, moved.__name__, stacklevel=3)
    sys.modules[alias] = moved


class MovedNames:
    """A subpackage's module ``__getattr__`` (PEP 562) for the names it used to re-export from its
    modules: ``from tensegrity_stiffness.estimation import JointFilter`` imports
    ``estimation.joint_filter`` then and returns its ``JointFilter``, with a
    :class:`DeprecationWarning` naming ``tensegrity_stiffness.estimation.joint_filter.JointFilter``
    at every use (nothing is cached, so the test configuration's error catches every use).

    ``modules``: the subpackage's modules, relative (``'joint_filter'``), each with the names it
    gives (None: its ``__all__``), searched in this order. ``__all__`` of the package is their
    union (a star import still gives every name, each with its warning). Any other name raises
    :class:`AttributeError`, which is what lets ``from package import submodule`` import it.
    """

    def __init__(self, package: str, modules: Mapping[str, Sequence[str] | None]) -> None:
        self.package = package
        self.modules = dict(modules)

    def module_names(self, relative: str) -> tuple[ModuleType, Sequence[str]]:
        """The subpackage's module ``relative`` (imported on first use) and the names it gives."""
        module = importlib.import_module(f'{self.package}.{relative}')
        names = self.modules[relative]
        return module, module.__all__ if names is None else names

    def is_submodule(self, name: str) -> bool:
        """Whether ``name`` is a module of the subpackage (``from package import submodule``
        asks the package for it first): answered without importing the moved names' modules,
        which may be the very ones importing it, part-way through their own import."""
        return importlib.util.find_spec(f'{self.package}.{name}') is not None

    def names(self) -> list[str]:
        """Every moved name, in the order of ``modules``."""
        return [name for relative in self.modules for name in self.module_names(relative)[1]]

    def __call__(self, name: str) -> object:
        if name == '__all__':
            return self.names()
        if not name.startswith('_') and not self.is_submodule(name):
            for relative in self.modules:
                module, names = self.module_names(relative)
                if name in names:
                    # this method (1), the code that asked the package for the name (2)
                    deprecated(f'{self.package}.{name}', f'{module.__name__}.{name}',
                               stacklevel=2)
                    return getattr(module, name)
        raise AttributeError(f'module {self.package!r} has no attribute {name!r}')
