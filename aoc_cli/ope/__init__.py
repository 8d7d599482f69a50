"""Offline policy evaluation: the estimators (PDWIS, WDR, ESS, the bootstrap), fitted Q
evaluation (FQE), its batched ensemble and the parts it trains in over forked processes, and
the OPE of the policies that ``aoc evaluate`` compares (docs/design.md, "Offline policy
evaluation").

- :mod:`aoc_cli.ope.estimators`: importance sampling and doubly robust estimates of a log;
- :mod:`aoc_cli.ope.fqe`: FQE of one or more policies, with its interval by refits;
- :mod:`aoc_cli.ope.ensemble`: the FQE networks of several policies trained as one batch;
- :mod:`aoc_cli.ope.parts`: that ensemble split over processes;
- :mod:`aoc_cli.ope.propensity`: the behaviour estimated from a log without propensities;
- :mod:`aoc_cli.ope.support`: what the log supports (the rule that withholds), the verdict;
- :mod:`aoc_cli.ope.value`: one policy's estimates, improvement and verdict;
- :mod:`aoc_cli.ope.evaluate_block`: the OPE block of ``aoc evaluate`` (settings, behaviour fit).
"""
