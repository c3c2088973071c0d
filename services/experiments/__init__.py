"""The paper's simulation experiments (§V-A): ARROCH against the no-feedback and no-comm baselines.

``arroch experiment robots`` varies the team size, ``arroch experiment laziness`` the human's
door-opening probability; each trial runs the real planner, restrictor and sim as processes over
Zenoh in lockstep mode on a generated site. ``arroch experiment report DIR`` turns a results folder
into tables, figures, significance tests and a check of the paper's claims.

Modules, one job each: :mod:`.design` (sweeps, trials, seeds), :mod:`.trial` (one trial's
processes), :mod:`.routers` and :mod:`.monitor` (Zenoh routers and the runner's view of a trial),
:mod:`.record` (outcome → CSV rows), :mod:`.store` (crash-safe CSV/JSONL files), :mod:`.runner`
(the sweep: workers, resume, signals), :mod:`.progress` (bar and time left), :mod:`.params`
(the model's parameters), :mod:`.results` (reading a results folder), :mod:`.stats` (confidence
intervals, tests, effect sizes), :mod:`.claims` (the paper's claims against the numbers),
:mod:`.plots` (figures), :mod:`.report` (tables and the Markdown report), :mod:`.cli`.
"""
