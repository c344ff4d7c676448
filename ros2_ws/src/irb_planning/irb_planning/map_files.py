"""Friction-map files a planning request may name: where they may come from, and how they are read.

A request's ``friction_map`` is a file name chosen by whoever calls the service, so the planner
reads it like untrusted input (no ROS imports):

* only from the configured directories (``friction_map_dirs``; default: the share directory of
  irb_description, where the model's files live, and ``runs/`` and ``bags/`` of the workspace,
  ``$IRB_ROOT`` or the working directory); a relative name is looked up in them in order, an
  absolute one must lie inside one of them after symlinks are resolved;
* a regular ``.yaml``/``.yml`` file of at most ``MAX_BYTES``, UTF-8, a YAML mapping;
* every number checked before the model sees it: finite, friction coefficients >= 0 and below
  ``MAX_COEFFICIENT``, Stribeck speed > 0, a valid speed range, polynomials of sane size.

Every refusal is a ``PlanError(ERROR_FRICTION_MAP)`` whose message is ours: it names the file,
the joint and the field, never the file's contents (a YAML syntax error gives its line and
column only).
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import yaml
from irb_description.friction import FrictionMap, FrictionMapError, friction_map_from_dict
from irb_description.params import yaml_where

from .request import ERROR_FRICTION_MAP, PlanError

MAX_BYTES = 1 << 20               # 1 MiB
MAX_NAME = 1024                   # characters of the requested name
MAX_COEFFICIENT = 1.0e4           # N m, N m s/rad
MAX_POLYNOMIAL_TERMS = 12
MAX_POLYNOMIAL_COEFFICIENT = 1.0e9
SUFFIXES = ('.yaml', '.yml')
#: fields of a joint that are friction levels (>= 0); the schema of irb_description's
#: friction.py plus the asymmetric/offset fields of identified maps where present
LEVELS = ('coulomb', 'static', 'viscous', 'coulomb_positive', 'coulomb_negative',
          'static_positive', 'static_negative')
SIGNED = ('offset',)


def default_map_dirs() -> list[Path]:
    """irb_description's share directory, and runs/ and bags/ of the workspace."""
    dirs = []
    try:
        from ament_index_python.packages import get_package_share_directory
        dirs.append(Path(get_package_share_directory('irb_description')))
    except (ImportError, LookupError, ValueError):
        pass
    root = Path(os.environ.get('IRB_ROOT') or os.getcwd())
    dirs += [root / 'runs', root / 'bags']
    return dirs


def _fail(message: str):
    raise PlanError(ERROR_FRICTION_MAP, message)


def resolve_map_path(name: str, allowed_dirs) -> Path:
    """The file a request's ``friction_map`` names, resolved inside ``allowed_dirs``."""
    if len(name) > MAX_NAME or '\x00' in name:
        _fail(f'friction map name refused: longer than {MAX_NAME} characters or not text')
    dirs = [Path(d).resolve() for d in allowed_dirs]
    shown = ', '.join(str(d) for d in dirs) or '(none configured)'
    p = Path(name)
    candidates = [p] if p.is_absolute() else [d / p for d in dirs]
    for c in candidates:
        try:
            real = c.resolve()
            exists = real.is_file()
        except (OSError, RuntimeError):
            continue
        if not any(real == d or d in real.parents for d in dirs):
            _fail(f'friction map {name}: outside the allowed directories ({shown}); '
                  'see the planner parameter friction_map_dirs')
        if exists:
            return real
    _fail(f'friction map {name}: no such file in the allowed directories ({shown})')


def _number(joint: str, key: str, value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        _fail(f'{where}: joint {joint}: {key} is not a number')
    x = float(value)
    if not math.isfinite(x):
        _fail(f'{where}: joint {joint}: {key} is not finite')
    return x


def check_joint(joint: str, d, where: str) -> None:
    """Plausibility of one joint's entry (raises PlanError naming the field)."""
    if not isinstance(d, dict):
        _fail(f'{where}: joint {joint}: not a mapping')
    for key in ('coulomb', 'viscous'):
        if key not in d:
            _fail(f'{where}: joint {joint}: {key} missing')
    for key in LEVELS + SIGNED:
        if key in d:
            x = _number(joint, key, d[key], where)
            if key in LEVELS and x < 0:
                _fail(f'{where}: joint {joint}: {key} is negative (friction only dissipates)')
            if abs(x) > MAX_COEFFICIENT:
                _fail(f'{where}: joint {joint}: |{key}| exceeds {MAX_COEFFICIENT:g}')
    if 'stribeck_velocity' in d:
        vs = _number(joint, 'stribeck_velocity', d['stribeck_velocity'], where)
        if not 0 < vs <= 100:
            _fail(f'{where}: joint {joint}: stribeck_velocity must be in (0, 100] rad/s')
    if 'valid_range' in d:
        vr = d['valid_range']
        if not isinstance(vr, (list, tuple)) or len(vr) != 2:
            _fail(f'{where}: joint {joint}: valid_range must be [low, high] in rad/s')
        lo = _number(joint, 'valid_range', vr[0], where)
        hi = math.inf if vr[1] == math.inf else _number(joint, 'valid_range', vr[1], where)
        if not 0 <= lo < hi:
            _fail(f'{where}: joint {joint}: valid_range must satisfy 0 <= low < high')
    for key in ('polynomial_positive', 'polynomial_negative'):
        if key in d:
            c = d[key]
            if not isinstance(c, (list, tuple)) or not 1 <= len(c) <= MAX_POLYNOMIAL_TERMS:
                _fail(f'{where}: joint {joint}: {key} must be a list of 1 to '
                      f'{MAX_POLYNOMIAL_TERMS} coefficients')
            for x in c:
                if abs(_number(joint, key, x, where)) > MAX_POLYNOMIAL_COEFFICIENT:
                    _fail(f'{where}: joint {joint}: a {key} coefficient exceeds '
                          f'{MAX_POLYNOMIAL_COEFFICIENT:g}')
    if ('polynomial_positive' in d) != ('polynomial_negative' in d):
        _fail(f'{where}: joint {joint}: polynomials must be given for both signs')


def read_map(path: Path, joint_names: list[str]) -> tuple[FrictionMap, dict]:
    """(FrictionMap for the model's joints, the file's checked ``friction_map`` mapping)."""
    where = f'friction map {path.name}'
    if path.suffix.lower() not in SUFFIXES:
        _fail(f'{where}: not a YAML file ({" or ".join(SUFFIXES)})')
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            _fail(f'{where}: {size} bytes, more than the {MAX_BYTES} allowed')
        text = path.read_bytes().decode('utf-8')
    except UnicodeDecodeError:
        _fail(f'{where}: not a text file (UTF-8)')
    except OSError as exc:
        _fail(f'{where}: cannot be read ({exc.strerror or "I/O error"})')
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        _fail(f'{where}: not valid YAML{yaml_where(exc)}')
    block = data.get('friction_map') if isinstance(data, dict) else None
    if not isinstance(block, dict) or not isinstance(block.get('joints'), dict):
        _fail(f'{where}: no friction_map.joints mapping (see irb_description friction.py)')
    missing = [n for n in joint_names if n not in block['joints']]
    if missing:
        _fail(f'{where}: no entry for {missing}')
    for name in joint_names:
        check_joint(name, block['joints'][name], where)
    try:
        fm = friction_map_from_dict(data, joint_names)
    except FrictionMapError as exc:       # the version, or a field the checks above missed
        _fail(f'{where}: not a usable friction map ({str(exc).split("(")[0].strip()})')
    return fm, block
