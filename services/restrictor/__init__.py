"""The restrictor (paper §III-B): human feedback chosen from the constraint library F → ASP constraints.

Modules, one responsibility each:

- :mod:`.library`    the library file (``library.toml``): loading, validation, the site's choices;
- :mod:`.validate`   checking a client's feedback against the library and the site;
- :mod:`.compile`    filling templates with validated values and the time window;
- :mod:`.store`      SQLite persistence of the active set and of the answers given;
- :mod:`.active`     the active ConstraintSet: apply, withdraw, expire, answer duplicates;
- :mod:`.service`    the Zenoh process (``arroch restrictor``), which also serves the library;
- :mod:`.cli`        ``arroch restrictor``, ``arroch feedback send``, ``arroch constraints show|compile|library``.

What other services share with it lives in ``protocol/``: the ASP vocabulary and its check
(:mod:`protocol.asp_vocabulary`), the client side of feedback and of the live set
(:mod:`runtime.feedback_client`) and the library as it is served (:mod:`protocol.constraint_library`).
No other service imports this package.
"""
