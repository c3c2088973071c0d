"""The restrictor (paper §III-B): human feedback chosen from the constraint library F → ASP constraints.

Modules, one responsibility each:

- :mod:`.vocabulary` the ASP vocabulary shared with the planner, and the check every ASP text passes;
- :mod:`.library`    the library file (``library.toml``): loading, validation, the site's choices;
- :mod:`.validate`   checking a client's feedback against the library and the site;
- :mod:`.compile`    filling templates with validated values and the time window;
- :mod:`.store`      SQLite persistence of the active set and of the answers given;
- :mod:`.active`     the active ConstraintSet: apply, withdraw, expire, answer duplicates;
- :mod:`.service`    the Zenoh process (``arroch restrictor``);
- :mod:`.client`     sending feedback / fetching the set from a client;
- :mod:`.cli`        ``arroch restrictor``, ``arroch feedback send``, ``arroch constraints show|compile|library``.

Other services import :func:`library_for_site` (the library as the tablet shows it) and
:data:`VOCABULARY` from here.
"""

from .library import library_for_site, load_library
from .vocabulary import VOCABULARY, check_program

__all__ = ["VOCABULARY", "check_program", "library_for_site", "load_library"]
