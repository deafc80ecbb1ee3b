"""Checks that every array whose address goes to a compiled kernel lives until the call
returns: :func:`poisoned` (freed small buffers handed out again and NaN-filled before C runs)
and :func:`assert_asan_clean` (a script run against the kernel built with AddressSanitizer)."""

import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import tensegrity_stiffness
from tensegrity_stiffness.mechanics import kernel

#: Largest freed block (bytes) the poisoned calls hand out again and overwrite: numpy keeps
#: freed data buffers below 1024 bytes in a cache (per size, last freed first out); larger ones
#: go back to malloc, where the AddressSanitizer test sees them.
POISON_BYTES = 1016


def poisoned(call: Callable[..., Any]) -> Callable[..., Any]:
    """``call`` preceded by reallocating and NaN-filling every freed block up to
    :data:`POISON_BYTES` (kept until the call returns, so that C sees them overwritten)."""
    def poisoned_call(*args: Any) -> Any:
        held = [np.full(k, np.nan) for k in range(1, POISON_BYTES // 8 + 1)]
        try:
            return call(*args)
        finally:
            del held
    return poisoned_call


def kernel_sources() -> list[Path]:
    """The kernel's C++ sources of the checkout under test (this package's repository)."""
    root = Path(tensegrity_stiffness.__file__).resolve().parents[1]
    for folder in (root / 'tensegrity_stiffness_kernel' / 'src', root / 'src'):
        sources = sorted(folder.glob('*_kernel.cpp'))
        if sources:
            return sources
    pytest.fail(f'no kernel sources (*_kernel.cpp) under {root}')


def libasan() -> str:
    """The path of g++'s AddressSanitizer runtime (skips the test without g++ or it)."""
    if shutil.which('g++') is None:
        pytest.skip('no g++')
    done = subprocess.run(['g++', '-print-file-name=libasan.so'], capture_output=True,
                          text=True, check=False)
    path = done.stdout.strip()
    if done.returncode != 0 or not os.path.isabs(path):
        pytest.skip('g++ has no libasan')
    return path


def assert_asan_clean(tmp_path: Path, script: str) -> None:
    """Build the kernel with ``-fsanitize=address`` into ``tmp_path``, run ``script`` (Python
    that prints ``ok``) against it and assert that AddressSanitizer reports nothing."""
    asan = libasan()
    sources = kernel_sources()
    root = sources[0].parents[1]
    library = tmp_path / kernel.LIBRARY_NAME
    includes = [f'-I{root / "include"}'] if (root / 'include').is_dir() else []
    subprocess.run(['g++', '-std=c++17', '-O1', '-g', '-fsanitize=address',
                    '-fno-omit-frame-pointer', '-ffp-contract=off', '-shared', '-fPIC',
                    *includes, *map(str, sources), '-o', str(library)], check=True, timeout=300)
    env = dict(os.environ, LD_PRELOAD=asan, ASAN_OPTIONS='detect_leaks=0',
               TENSEGRITY_STIFFNESS_KERNEL=str(library))
    done = subprocess.run([sys.executable, '-c', script], env=env, capture_output=True,
                          text=True, timeout=120, check=False)
    report = done.stderr[-3000:]
    assert 'AddressSanitizer' not in done.stderr, report
    assert done.returncode == 0 and done.stdout.strip() == 'ok', report
