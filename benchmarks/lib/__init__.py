"""What the benchmark scripts share (a folder of its own: ``make bench`` runs every ``benchmarks/*.py``)."""
