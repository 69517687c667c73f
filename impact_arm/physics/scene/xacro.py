"""An arm described in xacro: expanded to its URDF text here, without a ROS install.

The scene key ``arm: {xacro: FILE, args: {...}, package_paths: [...]}`` (docs/scene.md, "A
xacro description") names a xacro file; :func:`expand_xacro` runs it through the ``xacro``
package (PyPI or ROS) and returns the URDF text, which the scene then reads as it reads
``arm.description`` (and which recordings store). ``$(find pkg)`` and ``package://pkg/...``
resolve through :class:`PackageIndex`: first the scene's ``package_paths``, directories that
either are a package (hold a ``package.xml`` whose ``<name>`` is the package) or contain
packages (as ``ROS_PACKAGE_PATH`` entries or a colcon workspace's ``src`` do), then the ament
index where ``ament_index_python`` is importable and knows the package. A source package's
directory stands for its share directory: description packages install ``urdf/``, ``meshes/``
and the like to ``share/<pkg>/`` as they are.

Every failure is a :class:`SceneError` in one line starting with the caller's ``origin``.
"""

from __future__ import annotations

import math
import os
import re
import threading
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any, NoReturn

from ..errors import SceneError

PACKAGE_NAME = re.compile(r'[A-Za-z][A-Za-z0-9_\-]*\Z')
IGNORE_MARKERS = ('COLCON_IGNORE', 'AMENT_IGNORE', 'CATKIN_IGNORE')
MAX_CRAWL_DEPTH = 5  # src/<repository>/<group>/<package>: deeper trees are not searched
MAX_CRAWL_DIRS = 20000  # a package path such as '/' is refused rather than crawled for minutes

# xacro keeps the document being expanded in module globals (its file and macro stacks, the
# substitution args, the list of included files), so two expansions at once in one process
# would corrupt each other: every expansion here holds this lock.
_XACRO_LOCK = threading.Lock()


class _Refusal(Exception):
    """A failure with its message for the user (without the origin): raised where xacro calls
    back into this module, found again in the exception xacro wraps it in."""


def _one_line(text: str) -> str:
    return ' '.join(str(text).split())


class PackageIndex:
    """Where packages are: ``package_paths`` (relative ones relative to ``base_dir``, or the
    working directory if it is empty), searched in order, the first package of a name found
    winning (as on ``ROS_PACKAGE_PATH``), then the ament index. A path that is not a
    directory is refused at once; the paths are crawled on the first look-up. Failures are
    ``SceneError`` in one line starting with ``origin``."""

    def __init__(self, package_paths: Sequence[str], origin: str, base_dir: str = '') -> None:
        self.origin = origin
        if isinstance(package_paths, (str, bytes)):
            self._fail(f'arm.package_paths = {package_paths!r}: must be a list of directories')
        self.paths: list[str] = []
        for entry in package_paths:
            if not isinstance(entry, str) or not entry:
                self._fail(f'arm.package_paths entry {entry!r}: must be a directory path')
            path = os.path.normpath(os.path.join(base_dir, os.path.expanduser(entry)))
            if not os.path.isdir(path):
                self._fail(f"arm.package_paths entry '{entry}': no such directory ({path})")
            self.paths.append(os.path.abspath(path))
        self._packages: dict[str, str] | None = None

    def _fail(self, message: str) -> NoReturn:
        raise SceneError(f'{self.origin}: {_one_line(message)}')

    def packages(self) -> dict[str, str]:
        """Package name -> directory, over all ``package_paths`` (crawled once)."""
        if self._packages is None:
            found: dict[str, str] = {}
            try:
                for path in self.paths:
                    for name, directory in _crawl(path):
                        found.setdefault(name, directory)
            except _Refusal as exc:
                self._fail(str(exc))
            self._packages = found
        return self._packages

    def find(self, name: str) -> str:
        """The directory of package ``name`` (``$(find name)``); if there is none, the
        message names the places searched and how to add one."""
        if not isinstance(name, str) or not PACKAGE_NAME.match(name):
            self._fail(f'$(find {name}): {name!r} is not a package name')
        directory = self.packages().get(name)
        if directory is not None:
            return directory
        share, ament = _ament_share_directory(name)
        if share is not None:
            return share
        searched = ', '.join(self.paths) if self.paths else 'none given'
        self._fail(
            f"package '{name}' not found: searched arm.package_paths ({searched}) and {ament}; "
            f'add its directory, or the directory holding it, to arm.package_paths'
        )

    def resolve_uri(self, uri: str) -> str:
        """The file a ``package://pkg/path`` or ``file://`` URI names (other text is taken as
        a path and returned as it is)."""
        if uri.startswith('package://'):
            name, _, rest = uri[len('package://') :].partition('/')
            if not name:
                self._fail(f"'{uri}' names no package")
            return os.path.join(self.find(name), *[p for p in rest.split('/') if p])
        if uri.startswith('file://'):
            return uri[len('file://') :]
        return uri


def _package_name(directory: str) -> str:
    """The ``<name>`` of ``directory``'s package.xml."""
    manifest = os.path.join(directory, 'package.xml')
    try:
        root = ET.parse(manifest).getroot()
    except (OSError, ET.ParseError) as exc:
        raise _Refusal(f"'{manifest}' cannot be read: {_one_line(str(exc))}") from None
    element = root.find('name')
    name = (element.text or '').strip() if element is not None else ''
    if not PACKAGE_NAME.match(name):
        raise _Refusal(f"'{manifest}' has no valid <name> (found {name!r})")
    return name


def _crawl(path: str) -> Iterator[tuple[str, str]]:
    """(name, directory) of the packages at or under ``path``, breadth first in name order
    (so that a shallower package wins), not looking inside a package, nor into hidden
    directories or those marked COLCON_IGNORE, AMENT_IGNORE or CATKIN_IGNORE."""
    level = [path]
    visited = 0
    for _ in range(MAX_CRAWL_DEPTH + 1):
        below: list[str] = []
        for directory in level:
            visited += 1
            if visited > MAX_CRAWL_DIRS:
                raise _Refusal(
                    f"arm.package_paths entry '{path}' holds more than {MAX_CRAWL_DIRS} "
                    f'directories: give the packages or the directory right above them'
                )
            if os.path.isfile(os.path.join(directory, 'package.xml')):
                yield _package_name(directory), directory
                continue
            if any(os.path.exists(os.path.join(directory, m)) for m in IGNORE_MARKERS):
                continue
            try:
                names = sorted(os.listdir(directory))
            except OSError:
                continue
            below += [
                os.path.join(directory, n)
                for n in names
                if not n.startswith('.') and os.path.isdir(os.path.join(directory, n))
            ]
        level = below
        if not level:
            return


def _ament_share_directory(name: str) -> tuple[str | None, str]:
    """The package's share directory from the ament index, if there is one that knows it, and
    what was searched (for the message when there is not)."""
    try:
        from ament_index_python.packages import get_package_share_directory
    except ImportError:
        return None, 'no ament index (ament_index_python is not installed)'
    prefix = os.environ.get('AMENT_PREFIX_PATH')
    if not prefix:
        return None, 'no ament index (AMENT_PREFIX_PATH is not set)'
    try:
        return get_package_share_directory(name, print_warning=False), ''
    except (LookupError, ValueError, OSError):
        return None, f'the ament index (AMENT_PREFIX_PATH={prefix})'


def find_package(name: str, package_paths: Sequence[str], origin: str, base_dir: str = '') -> str:
    """The directory ``$(find name)`` gives (``PackageIndex``), or ``SceneError`` in one line
    starting with ``origin``."""
    return PackageIndex(package_paths, origin, base_dir).find(name)


def resolve_package_uri(
    uri: str, package_paths: Sequence[str], origin: str = 'package URI', base_dir: str = ''
) -> str:
    """The file a ``package://pkg/path`` URI names, the package found as ``$(find pkg)``
    finds it; a ``file://`` URI's path; any other text as it is. ``SceneError`` in one line
    starting with ``origin`` if the package is not found."""
    return PackageIndex(package_paths, origin, base_dir).resolve_uri(uri)


def _arg_text(name: str, value: Any) -> str:
    """A scene's ``arm.args`` value as the string xacro takes: booleans ``true``/``false``,
    numbers in a form xacro reads back as the same number, strings as they are."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise _Refusal(f"arm.args '{name}' = {value}: must be a finite number")
        text = repr(value)
        # xacro reads a number without a '.' as an int: 1e-05 would stay the string '1e-05'
        return text.replace('e', '.0e', 1) if 'e' in text and '.' not in text else text
    if isinstance(value, str):
        return value
    raise _Refusal(
        f"arm.args '{name}' = {value!r}: must be a string, a number or a boolean, "
        f'not a {type(value).__name__}'
    )


class _ArgsSeen(dict):
    """The args xacro is given, noting each name it looks up (``$(arg)``, ``xacro:arg``, its
    ``$(eval arg(...))``), so that a scene's arg the file never reads is told as a typo."""

    def __init__(self, values: Mapping[str, str]) -> None:
        super().__init__(values)
        self.seen: set[str] = set()

    def __getitem__(self, key: str) -> str:
        self.seen.add(key)
        return super().__getitem__(key)

    def __contains__(self, key: object) -> bool:
        if isinstance(key, str):
            self.seen.add(key)
        return super().__contains__(key)


@contextmanager
def _xacro_session(find: Callable[[str], str]) -> Iterator[Any]:
    """The ``xacro`` module with ``$(find)`` resolving through ``find``, serialised, and left
    as it was found afterwards.

    Why substitute xacro's find function: xacro resolves ``$(find pkg)`` by calling
    ``substitution_args._eval_find`` (which asks ``ament_index_python``), and ``$(eval
    find(...))`` through the same function kept in ``substitution_args._eval_dict``; there
    is no parameter for it. The alternatives are worse: a temporary ament prefix (a
    directory tree of marker files and links to each package, plus ``AMENT_PREFIX_PATH``
    changed for the whole process) or rewriting ``$(find ...)`` in the text (which misses
    included files and finds built from properties). The substitution holds only inside
    the lock xacro's module-level state needs anyway, and the original is put back even
    when the expansion fails."""
    try:
        import xacro
        from xacro import substitution_args
    except ImportError:
        raise _Refusal('needs the xacro package: pip install xacro') from None
    missing = [
        name
        for owner, name in (
            (substitution_args, '_eval_find'),
            (substitution_args, '_eval_dict'),
            (xacro, 'process_doc'),
            (xacro, 'init_stacks'),
            (xacro, 'parse'),
        )
        if not hasattr(owner, name)
    ]
    if missing:  # a xacro release this module was not written for: say so, not a traceback
        raise _Refusal(
            f'the installed xacro ({getattr(xacro, "__file__", "?")}) lacks {", ".join(missing)}: '
            f'install xacro 2.x (pip install "xacro>=2,<3")'
        )

    def eval_find(name: str) -> str:
        return find(name)

    with _XACRO_LOCK:
        saved_find = substitution_args._eval_find
        saved_eval_find = substitution_args._eval_dict.get('find')
        saved_includes = list(getattr(xacro, 'all_includes', []))
        saved_verbosity = getattr(xacro, 'verbosity', 1)
        substitution_args._eval_find = eval_find
        substitution_args._eval_dict['find'] = eval_find
        try:
            yield xacro
        finally:
            substitution_args._eval_find = saved_find
            substitution_args._eval_dict['find'] = saved_eval_find
            xacro.all_includes = saved_includes
            xacro.verbosity = saved_verbosity
            xacro.substitution_args_context['arg'] = {}
            xacro.filestack = None
            xacro.macrostack = None


def _refusal_in(exc: BaseException) -> Exception | None:
    """Our refusal (a ``_Refusal``, or the ``SceneError`` of a package not found) where
    xacro wrapped it: its exceptions keep the cause in ``exc``."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        if isinstance(current, (_Refusal, SceneError)):
            return current
        seen.add(id(current))
        inner = getattr(current, 'exc', None)
        current = (
            inner
            if isinstance(inner, BaseException)
            else (current.__cause__ or current.__context__)
        )
    return None


def _xacro_message(exc: BaseException, xacro: Any, top: str) -> str:
    """One line for an exception out of xacro, naming the included file it happened in."""
    from xml.parsers.expat import ExpatError

    from xacro.substitution_args import ArgException, SubstitutionException

    inner: Any = getattr(exc, 'exc', None)
    while isinstance(getattr(inner, 'exc', None), BaseException):
        inner = inner.exc
    if isinstance(exc, ExpatError):
        message = f'not well-formed XML: {exc}'
    elif isinstance(inner, ArgException):
        message = (
            f"xacro arg '{inner}' has no value: give it in arm.args "
            f'(the file declares no default for it with <xacro:arg>)'
        )
    elif isinstance(inner, SubstitutionException):  # xacro repeats it after its class
        message = f'$(...): {inner}'
    elif isinstance(inner, OSError) and inner.filename:
        message = f"cannot read '{inner.filename}': {inner.strerror}"
    elif inner is not None and str(exc).startswith(f'{type(inner)}: '):  # from a $(...)
        message = f'$(...): {type(inner).__name__}: {inner}'
    else:
        message = str(exc) or type(exc).__name__
        if isinstance(inner, NameError):
            message = f'undefined property or name: {message}'
    stack = [f for f in (getattr(xacro, 'filestack', None) or []) if f]
    where = stack[-1] if stack else top
    if os.path.abspath(where) != os.path.abspath(top):
        message += f' (in {where})'
    return _one_line(message)


def expand_xacro(
    path: str,
    args: Mapping[str, Any] | None,
    package_paths: Sequence[str],
    origin: str,
    base_dir: str = '',
) -> str:
    """The URDF text of the xacro file ``path`` with the xacro ``args`` (name -> string,
    number or boolean; a file's ``<xacro:arg>`` defaults fill the rest), ``$(find pkg)``
    resolved through ``package_paths`` and then the ament index (``PackageIndex``). A
    relative ``path`` and relative ``package_paths`` are relative to ``base_dir`` (the scene
    file's directory; empty: the working directory).

    ``SceneError`` in one line starting with ``origin`` (e.g. ``scene 'X': arm.xacro
    'robot.urdf.xacro'``) if the file is missing or unreadable, is not well-formed XML, uses
    an undefined property, a package that is not found or an arg without a value, if a
    scene arg is not one the file reads, or if the result is not a ``<robot>``.

    The text begins with a comment naming the file (its base name: the text is the same on
    every machine) and the args; ``package://`` URIs in it are left as they are (a mesh is
    found with ``resolve_package_uri``)."""

    def fail(message: str) -> SceneError:
        return SceneError(f'{origin}: {_one_line(message)}')

    index = PackageIndex(package_paths, origin, base_dir)
    full = os.path.abspath(os.path.join(base_dir, os.path.expanduser(path)))
    if not os.path.isfile(full):
        raise fail(f'no such file ({full})' if not os.path.exists(full) else f'not a file ({full})')
    try:
        given = {str(k): _arg_text(str(k), v) for k, v in (args or {}).items()}
        with _xacro_session(index.find) as xacro:
            mappings = _ArgsSeen(given)
            try:
                xacro.init_stacks(full)
                doc = xacro.parse(None, full)
                xacro.process_doc(doc, mappings=mappings, verbosity=0)
            except Exception as exc:  # xacro raises its own, expat's, and any eval error
                refusal = _refusal_in(exc)
                if refusal is not None:
                    raise refusal from None
                raise _Refusal(_xacro_message(exc, xacro, full)) from None
            unread = sorted(set(given) - mappings.seen)
            if unread:
                reads = ', '.join(sorted(mappings.seen)) or 'none'
                raise _Refusal(
                    f'arm.args {", ".join(repr(n) for n in unread)}: not an arg of this file '
                    f'(it reads: {reads})'
                )
            root = doc.documentElement
            if root is None or root.tagName != 'robot':
                tag = root.tagName if root is not None else 'nothing'
                raise _Refusal(f'expands to <{tag}>, not a URDF <robot>')
            described = ', '.join(f'{k}={v!r}' for k, v in sorted(mappings.items()))
            note = f' expanded by xacro from {os.path.basename(full)}' + (
                f' with args {described} ' if described else ' '
            )
            doc.insertBefore(doc.createComment(note.replace('--', '- -')), doc.firstChild)
            return str(doc.toprettyxml(indent='  '))
    except _Refusal as exc:
        raise fail(str(exc)) from None
