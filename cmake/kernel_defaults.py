"""Write include/tensegrity_stiffness/kernel_defaults.h (CMakeLists.txt runs it at build time).

Usage: ``python kernel_defaults.py SOURCE_DIR OUTPUT``. The text is
``tensegrity_stiffness.mechanics.kernel.defaults_header()`` of the package in SOURCE_DIR; the file
is rewritten only when it changes (no rebuild of its includers otherwise).
"""

import sys
from pathlib import Path


def main(source: Path, output: Path) -> None:
    sys.path.insert(0, str(source))
    from tensegrity_stiffness.mechanics.kernel import defaults_header

    text = defaults_header()
    if not output.is_file() or output.read_text() != text:
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_text(text)


if __name__ == '__main__':
    main(Path(sys.argv[1]), Path(sys.argv[2]))
