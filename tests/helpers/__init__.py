"""Code shared by several test modules, one topic per module; test modules import it as
``from tests.helpers.<topic> import ...`` and never import each other."""
