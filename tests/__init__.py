"""The test suite (a package, so that test modules import shared code one way:
``from tests.helpers.<topic> import ...``).

Layout: ``helpers/`` code shared between test modules (plants, builders, listeners);
``fuzz/`` the parser fuzzing (corpora, targets, property and regression tests, the
``slow`` campaign); ``data/`` small committed inputs with their expected outputs.
Markers (pyproject.toml): ``integration`` for tests over sockets, pseudo-terminals,
child processes or Zenoh sessions; every other test is marked ``unit`` by conftest.py;
``slow`` and ``data`` as documented there.
"""
