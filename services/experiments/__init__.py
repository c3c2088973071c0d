"""The paper's simulation experiments (§V-A): ARROCH against the no-feedback and no-comm baselines,
and experiments on ARROCH's mechanism.

``arroch experiment robots`` varies the team size, ``arroch experiment laziness`` the human's
door-opening probability, ``arroch experiment map`` her task length and the cost of an interruption;
``detour`` runs a task the planner can reorder (only some deliveries behind her door, robot capacity
1-3), ``sensitivity`` screens the human model's and the domain's parameters (Morris, then Sobol),
``population`` runs simulated people drawn from priors. Each trial runs the real planner, restrictor
and sim as processes over Zenoh in lockstep mode on a generated site. ``arroch experiment report
DIR`` turns a results folder into tables, figures, significance tests and a check of the claims.

Modules, one job each: :mod:`.design` (sweeps, trials, seeds), :mod:`.factors` (what a point sets and
where it goes), :mod:`.trial` (one trial's processes), :mod:`.routers` and :mod:`.monitor` (Zenoh
routers and the runner's view of a trial), :mod:`.plan_changes` (how feedback changed the plans),
:mod:`.record` (outcome → CSV rows), :mod:`.store` (crash-safe CSV/JSONL files), :mod:`.runner`
(the sweep: workers, resume, signals), :mod:`.progress` (bar and time left), :mod:`.params`
(the model's parameters), :mod:`.results` (reading a results folder), :mod:`.stats` (confidence
intervals, tests, effect sizes), :mod:`.comparisons` (the tested metrics and their verdicts),
:mod:`.claims` (the claims against the numbers), :mod:`.plots` and :mod:`.maps` (figures),
:mod:`.report` (tables and the Markdown report), :mod:`.sensitivity` and :mod:`.sensitivity_report`
(the sensitivity analysis), :mod:`.population` and :mod:`.mixed` (a population and its mixed
model), :mod:`.cli`.
"""
