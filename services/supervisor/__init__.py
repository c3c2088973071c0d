"""``arroch up`` (supervised local runs) and ``arroch deploy`` (certificates, per-host Zenoh configs).

Modules: :mod:`.cli` (the ``up`` command line), :mod:`.supervisor` (the run itself),
:mod:`.catalog` (which services exist and how each one's command line is built),
:mod:`.children` (processes, restart policy, stopping), :mod:`.launch` (exec wrapper tying children
to the supervisor's life), :mod:`.output` (merged prefixed output, progress bar), :mod:`.progress`
(mission progress from events and statuses), :mod:`.rundir` (``runs/<timestamp>/``), and
:mod:`.deployment` (``arroch deploy``: certificates, config rendering, access control).
"""
