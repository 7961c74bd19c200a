"""The experiment kinds: what ``kind = "..."`` in an experiment file runs, and the analysis each does.

Each module registers one kind through :func:`pursuit.registry.register`
(kind ``"experiment"``): ``montecarlo`` (:mod:`.montecarlo`), ``conditions``
(:mod:`.conditions`), ``sweep`` (:mod:`.sweep`) and ``maneuver``
(:mod:`.maneuver`).  A kind builds its sections through :mod:`pursuit.config`
and returns a :class:`pursuit.tables.ExperimentOutput`.  The registry imports
every module here on first use; the library itself imports none of them.
"""
