"""The bundled data, installed as the package ``onboard.bundled`` (pyproject.toml maps this
folder there): one TOML per vehicle class and deployment, and under ``gains/`` the
high-gain observer's designed gains per class. Data only, no code: the loader is
``onboard.core.config``, which finds these files with :mod:`importlib.resources`, so a
wheel installed anywhere reads the same files as this checkout."""
