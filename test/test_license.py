"""The licence the package declares is the one it ships."""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_license_file_is_the_declared_licence():
    declared_xml = re.search(r'<license>([^<]+)</license>', (ROOT / 'package.xml').read_text())
    declared_py = re.search(r"license='([^']+)'", (ROOT / 'setup.py').read_text())
    assert declared_xml.group(1) == declared_py.group(1) == 'Apache-2.0'
    text = (ROOT / 'LICENSE').read_text(encoding='utf-8')
    assert 'Apache License' in text and 'Version 2.0, January 2004' in text
    assert 'END OF TERMS AND CONDITIONS' in text
