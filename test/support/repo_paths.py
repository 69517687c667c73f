"""Where the tests find the repository's files, wherever in test/ a test module sits."""

import os

SUPPORT_DIR = os.path.dirname(os.path.abspath(__file__))  # helpers and stand-in scripts
TEST_DIR = os.path.dirname(SUPPORT_DIR)
TEST_DATA = os.path.join(TEST_DIR, 'data')  # descriptions written for the tests
REPO_ROOT = os.path.dirname(TEST_DIR)
EXAMPLES = os.path.join(REPO_ROOT, 'examples')
CONFIG = os.path.join(REPO_ROOT, 'config')
