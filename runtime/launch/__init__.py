"""Starting ARROCH processes as supervised children, shared by ``arroch up`` and the experiment runner.

- :mod:`.catalog`   the one table of how each service's process is started (sub-command, options,
  start order) and the command lines built from it;
- :mod:`.children`  child processes: start, watch, restart with backoff, stop without leftovers;
- :mod:`.pdeath`    the exec wrapper that makes a child die with its parent (``PR_SET_PDEATHSIG``).
"""
