"""
The experiment layer, built on the library and never imported by it: the RL-Zoo entry (``zoo``), the paper's
transfer challenges (``challenges``), plots, statistics and the demo. Each runs as ``python -m sb3_pilot.experiments.X``.
The measurement scripts behind the committed results are the repository's ``benchmarks/``, not part of the package.
"""
