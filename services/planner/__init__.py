"""The ARROCH planner: multi-robot task planning over ASP (clingo) with IIDP or one joint program,
a grid motion planner for trajectories, and the service that dispatches and replans (paper §III-C,
Algorithm 1 lines 2, 9 and 15). See docs/services/planner.md."""
