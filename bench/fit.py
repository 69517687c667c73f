#!/usr/bin/env python3
"""`python bench/fit.py [options]` = `impact-arm bench fit [options]` (see impact_arm/benchmarks)."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from impact_arm.tools.benchmarks import main  # noqa: E402

if __name__ == '__main__':
    sys.exit(main(['fit'] + sys.argv[1:]))
