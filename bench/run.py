#!/usr/bin/env python3
"""`python bench/run.py speed [options]` is `impact-arm bench speed [options]` (docs/benchmarks.md):
the benchmarks of bench/impact_arm_bench, run from a clone of the repository."""

import sys

# Python puts this script's folder, bench/, first on the path: impact_arm_bench is found there
from impact_arm_bench import main

if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
