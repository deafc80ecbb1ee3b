"""Test suite root: ``test/<area>/`` mirrors ``tensegrity_stiffness/<area>/`` (``ros/`` the
nodes, ``kernel/`` the compiled kernel, ``package/`` the layout, docs and builds); the shared
harnesses are the :mod:`support` package beside this file, importable because pytest puts this
folder on ``sys.path`` for its ``conftest.py``."""
