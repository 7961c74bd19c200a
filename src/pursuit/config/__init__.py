"""Registrations of scenarios, filters, fading strategies and models for configs and the CLI.

Each module here maps TOML tables to pursuit objects through
:func:`pursuit.registry.register`; :mod:`.build` builds a config's sections
from them.  The registry imports every module here on first use; the library
itself does not import this package (only the config loader and the CLI do).
"""
