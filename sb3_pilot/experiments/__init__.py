"""
The experiment layer, built on the library and never imported by it: the RL-Zoo entry (``zoo``), the paper's
transfer challenges (``challenges``), benchmarks, plots and the demo. Each runs as ``python -m sb3_pilot.experiments.X``.
"""
