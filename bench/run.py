#!/usr/bin/env python3
"""`python bench/run.py speed [options]` is `impact-arm bench speed [options]` (docs/benchmarks.md):
the benchmarks of bench/impact_arm_bench, run from a clone of the repository."""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from impact_arm_bench import main  # noqa: E402

if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
