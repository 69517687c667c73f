"""Builds the interface package ``simulation_interfaces`` for the tests, from the interface
files in test/interfaces/simulation_interfaces (written from the standard's public
specification), with the rosidl generators PyPI carries (requirements-dev.txt: ament_cmake,
rosidl_default_generators). CMake and a C compiler do the rest, as colcon would.

The result is kept in ~/.cache/impact_arm/simulation_interfaces-<hash> (the hash covers the
interface files, the Python and the ROS prefix), so only the first test session pays the
~30 s build. ``build()`` returns the install prefix; ``environment(prefix, env)`` the
variables a process needs to import the package.
"""

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

SOURCE = Path(__file__).parent / 'interfaces' / 'simulation_interfaces'
PY = f'python{sys.version_info.major}.{sys.version_info.minor}'


class Unavailable(Exception):
    """The build tools are missing: the reason, in one line."""


def _key() -> str:
    h = hashlib.sha256()
    for path in sorted(SOURCE.rglob('*')):
        if path.is_file():
            h.update(str(path.relative_to(SOURCE)).encode() + path.read_bytes())
    h.update(sys.version.encode() + sys.prefix.encode())
    return h.hexdigest()[:16]


def _check_tools():
    for tool in ('cmake', 'cc'):
        if shutil.which(tool) is None:
            raise Unavailable(f'{tool} is not installed')
    share = Path(sys.prefix) / 'share'
    for package in ('ament_cmake', 'rosidl_default_generators'):
        if not (share / package).is_dir():
            raise Unavailable(f'{package} is not installed (pip install -r requirements-dev.txt)')


def build() -> Path:
    """The install prefix of the built package (built once, then cached)."""
    cache = Path(os.environ.get('XDG_CACHE_HOME', Path.home() / '.cache')) / 'impact_arm'
    prefix = cache / f'simulation_interfaces-{_key()}'
    if (prefix / '.built').exists():
        return prefix
    _check_tools()
    cache.mkdir(parents=True, exist_ok=True)
    with open(cache / 'simulation_interfaces.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one build at a time, others wait for it
        if (prefix / '.built').exists():
            return prefix
        work = prefix.with_name(prefix.name + '.build')
        shutil.rmtree(work, ignore_errors=True)
        shutil.rmtree(prefix, ignore_errors=True)
        venv = sys.prefix
        env = dict(
            os.environ,
            AMENT_PREFIX_PATH=venv,
            CMAKE_PREFIX_PATH=venv,
            PATH=os.path.join(venv, 'bin') + os.pathsep + os.environ.get('PATH', ''),
        )
        generator = ['-G', 'Ninja'] if shutil.which('ninja') else []
        steps = [
            [
                'cmake',
                '-S',
                str(SOURCE),
                '-B',
                str(work),
                *generator,
                f'-DCMAKE_INSTALL_PREFIX={prefix}',
                f'-DPython3_EXECUTABLE={sys.executable}',
                '-DPython3_FIND_VIRTUALENV=ONLY',
                '-DBUILD_TESTING=OFF',
            ],
            ['cmake', '--build', str(work), '--parallel', '2'],
            ['cmake', '--install', str(work)],
        ]
        for step in steps:
            proc = subprocess.run(step, env=env, capture_output=True, text=True, timeout=900)
            if proc.returncode != 0:
                raise RuntimeError(
                    f'{" ".join(step[:2])} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}'
                )
        shutil.rmtree(work, ignore_errors=True)
        (prefix / '.built').touch()
    return prefix


def environment(prefix: Path, env: dict) -> dict:
    """``env`` with the package importable (Python path, libraries, ament index)."""

    def prepend(name, value):
        old = env.get(name, '')
        return value + (os.pathsep + old if old else '')

    out = dict(env)
    out['PYTHONPATH'] = prepend('PYTHONPATH', str(prefix / 'lib' / PY / 'site-packages'))
    out['LD_LIBRARY_PATH'] = prepend('LD_LIBRARY_PATH', str(prefix / 'lib'))
    out['AMENT_PREFIX_PATH'] = prepend('AMENT_PREFIX_PATH', str(prefix))
    return out
