"""An earlier checkout of this package imported beside it, so that a bench times the two in one
process, in alternation (``bench_dynamics.py --previous DIR``, ``bench_control.py --previous
DIR``). Make the checkout with ``git archive <commit> | tar -x -C DIR``; its compiled kernel is
built here from DIR's sources with CMakeLists.txt's flags. Run as a script
(``python3 bench/previous_checkout.py DIR [OUT]``) it builds that kernel and prints its path.
"""

from __future__ import annotations

import argparse
import importlib
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

PACKAGE = 'tensegrity_stiffness'
#: Environment variable of the kernel loader (``mechanics/kernel.py``'s ``KERNEL_ENV``).
KERNEL_ENV = 'TENSEGRITY_STIFFNESS_KERNEL'
LIBRARY_NAME = 'libtensegrity_stiffness_kernel.so'


def build_kernel(root: Path, out_dir: Path) -> Path:
    """The compiled kernel of the checkout ``root`` (its ``src/*.cpp``), built with g++ and the
    flags of CMakeLists.txt into ``out_dir``."""
    sources = sorted(str(p) for p in (root / 'src').glob('*.cpp'))
    if not sources:
        raise FileNotFoundError(f'no kernel sources under {root / "src"}')
    library = out_dir / LIBRARY_NAME
    subprocess.run(['g++', '-std=c++17', '-O2', '-ffp-contract=off', '-fno-fast-math', '-fPIC',
                    '-shared', f'-I{root / "include"}', *sources, '-o', str(library)],
                   check=True)
    return library


def import_modules(root: Path, names: list[str], library: Path) -> dict[str, ModuleType]:
    """The modules ``names`` (e.g. ``tensegrity_stiffness.mechanics.dynamics``) of the checkout
    ``root``, imported with its kernel ``library`` loaded; this package's modules are swapped out
    of ``sys.modules`` meanwhile and back after (the previous modules keep their own)."""
    ours = {k: v for k, v in sys.modules.items() if k == PACKAGE or k.startswith(PACKAGE + '.')}
    for name in ours:
        del sys.modules[name]
    setting = os.environ.get(KERNEL_ENV)
    os.environ[KERNEL_ENV] = str(library)
    sys.path.insert(0, str(root))
    try:
        out = {name: importlib.import_module(name) for name in names}
        kernel = importlib.import_module(f'{PACKAGE}.mechanics.kernel')
        kernel.status()  # loads the library now, under the setting above
        for module in out.values():
            assert Path(module.__file__).resolve().is_relative_to(root.resolve()), module
        out['kernel'] = kernel
    finally:
        sys.path.remove(str(root))
        for name in [k for k in sys.modules if k == PACKAGE or k.startswith(PACKAGE + '.')]:
            del sys.modules[name]
        sys.modules.update(ours)
        if setting is None:
            del os.environ[KERNEL_ENV]
        else:
            os.environ[KERNEL_ENV] = setting
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description='Build the compiled kernel of an earlier '
                                     'checkout (its src/*.cpp) and print the library path.')
    parser.add_argument('checkout', type=Path, help='the checkout (git archive C | tar -x -C DIR)')
    parser.add_argument('out', type=Path, nargs='?', help='folder for the library (default: a '
                        'new temporary one)')
    args = parser.parse_args()
    if args.out is None:
        import tempfile
        args.out = Path(tempfile.mkdtemp())
    args.out.mkdir(parents=True, exist_ok=True)
    print(build_kernel(args.checkout.resolve(), args.out))


if __name__ == '__main__':
    main()
