"""Packaged site files (TOML), read with ``importlib.resources``; ``office.toml`` is the default."""
