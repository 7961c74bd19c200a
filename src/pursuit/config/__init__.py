"""Registrations of scenarios, filters, models and experiment kinds for configs and the CLI.

Each module here maps TOML tables to pursuit objects through
:func:`pursuit.registry.register`.  The library itself does not import this
package; only the config loader and the CLI do.
"""
