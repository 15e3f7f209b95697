"""The monitor session (``ftc monitor``, ``ftc demo``) and ``ftc replay``: their options and outcome,
the run, its summary, the stop reflex, the simulated joint source, rehearsed faults, evaluation against
ground truth, the live terminal view."""
