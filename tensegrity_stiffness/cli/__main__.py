"""``python -m tensegrity_stiffness.cli``: the command line."""

import sys

from tensegrity_stiffness.cli.parser import main

sys.exit(main())
