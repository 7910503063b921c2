"""
Measurement scripts behind the committed results in ``zoo_runs/``: not part of the installed package. Each imports
only sb3-pilot's public API and runs from the repository root as ``python -m benchmarks.<name>``.
"""
