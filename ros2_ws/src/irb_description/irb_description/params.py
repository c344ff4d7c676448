"""Parameter files of the IRB 1600 description: locate, load, derive (no ROS imports).

All quantities are SI (m, kg, kg m^2, rad, rad/s, N m) once loaded; the YAML keys that hold
degrees or millimetres say so in their names and are converted here.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

PACKAGE = 'irb_description'
URDF_NAME = 'irb1600_6_12.urdf'


def share_dir() -> Path:
    """Directory holding ``config/`` and ``urdf/`` of irb_description.

    The installed share directory (ament index) when the package is installed, otherwise the
    source tree next to this module, so the library also works from a plain checkout.
    """
    source = Path(__file__).resolve().parent.parent
    if (source / 'config' / 'dynamics.yaml').is_file():
        return source
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory(PACKAGE))
    except Exception as exc:  # noqa: BLE001 - any lookup failure means "not installed"
        raise FileNotFoundError(
            f'{PACKAGE} share directory not found (source tree or ament index): {exc}') from exc


def config_path(name: str) -> Path:
    """Path of ``config/<name>`` in the description package."""
    return share_dir() / 'config' / name


def urdf_path() -> Path:
    """Path of the generated URDF."""
    return share_dir() / 'urdf' / URDF_NAME


def yaml_where(exc: Exception) -> str:
    """Where a YAML parse error is (1-based): " at line 3, column 9", or '' without a mark.
    Alone for messages that must not echo a file's content (irb_planning map_files)."""
    mark = getattr(exc, 'problem_mark', None)
    return f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''


def yaml_problem(exc: Exception) -> str:
    """One line for a YAML parse error: what is wrong and where (line and column, 1-based),
    e.g. "mapping values are not allowed here at line 3, column 9"."""
    return (getattr(exc, 'problem', None) or str(exc).splitlines()[0]) + yaml_where(exc)


def _load_yaml(path: Path) -> dict:
    with open(path, encoding='utf-8') as f:
        data = yaml.safe_load(f)
    if not isinstance(data, dict):
        raise ValueError(f'{path}: expected a mapping at the top level')
    return data


@dataclass(frozen=True)
class JointSpec:
    """One URDF joint: origin in the parent frame [m] and unit axis in the child frame."""

    name: str
    parent: str
    child: str
    xyz: np.ndarray   # (3,) [m]
    axis: np.ndarray  # (3,)


@dataclass(frozen=True)
class Kinematics:
    """Kinematic description (config/kinematics.yaml) in SI units."""

    joints: tuple[JointSpec, ...]
    tool0_xyz: np.ndarray      # (3,) [m] in link_6
    tool0_rpy: np.ndarray      # (3,) [rad]
    lower: np.ndarray          # (6,) [rad]
    upper: np.ndarray          # (6,) [rad]
    velocity: np.ndarray       # (6,) [rad/s]
    dh_a: np.ndarray           # (6,) [m]
    dh_alpha: np.ndarray       # (6,) [rad]
    dh_d: np.ndarray           # (6,) [m]
    dh_offset: np.ndarray      # (6,) [rad]

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]


def load_kinematics(path: Path | None = None) -> Kinematics:
    """Load ``config/kinematics.yaml`` (or ``path``)."""
    d = _load_yaml(path or config_path('kinematics.yaml'))
    joints = tuple(
        JointSpec(j['name'], j['parent'], j['child'], np.asarray(j['xyz'], float),
                  np.asarray(j['axis'], float)) for j in d['joints'])
    dh = d['dh_table']
    lim = d['position_limits_deg']
    return Kinematics(
        joints=joints,
        tool0_xyz=np.asarray(d['tool0']['xyz'], float),
        tool0_rpy=np.asarray(d['tool0']['rpy'], float),
        lower=np.radians(lim['lower']),
        upper=np.radians(lim['upper']),
        velocity=np.radians(d['velocity_limits_deg_s']),
        dh_a=np.asarray(dh['a_mm'], float) / 1000.0,
        dh_alpha=np.radians(dh['alpha_deg']),
        dh_d=np.asarray(dh['d_mm'], float) / 1000.0,
        dh_offset=np.radians(dh['theta_offset_deg']),
    )


def box_inertia(mass: float, size: np.ndarray) -> np.ndarray:
    """Rotational inertia (3, 3) [kg m^2] of a uniform solid box about its centre.

    ``size`` (3,) holds the edge lengths [m] along x, y, z.
    """
    lx, ly, lz = np.asarray(size, float)
    return mass / 12.0 * np.diag([ly**2 + lz**2, lx**2 + lz**2, lx**2 + ly**2])


@dataclass(frozen=True)
class LinkInertial:
    """Mass [kg], CoM (3,) [m] in the link frame, inertia (3, 3) [kg m^2] about the CoM.

    ``box`` (3,) [m] is the solid box the inertia was derived from (also the URDF visual).
    """

    name: str
    mass: float
    com: np.ndarray
    inertia: np.ndarray
    box: np.ndarray


@dataclass(frozen=True)
class Dynamics:
    """Dynamic parameters (config/dynamics.yaml) in SI units."""

    links: tuple[LinkInertial, ...]   # link_1, link_2, link_3 (= links 3-6 of the robot)
    gear_ratio: np.ndarray            # (6,)
    rotor_inertia: np.ndarray         # (6,) [kg m^2], motor side
    torque_limit: np.ndarray          # (6,) [N m], arm side
    friction: dict                    # raw friction block, see friction.FrictionMap

    @property
    def armature(self) -> np.ndarray:
        """Reflected rotor inertia ratio^2 * J_rotor, (6,) [kg m^2], arm side."""
        return self.gear_ratio**2 * self.rotor_inertia


def load_dynamics(path: Path | None = None) -> Dynamics:
    """Load ``config/dynamics.yaml`` (or ``path``); inertias follow from the box sizes."""
    d = _load_yaml(path or config_path('dynamics.yaml'))
    links = []
    for name in ('link_1', 'link_2', 'link_3'):
        ld = d['links'][name]
        mass = float(ld['mass'])
        box = np.asarray(ld['inertia_box_m'], float)
        links.append(LinkInertial(name, mass, np.asarray(ld['com_m'], float),
                                  box_inertia(mass, box), box))
    act = d['actuators']
    return Dynamics(
        links=tuple(links),
        gear_ratio=np.asarray(act['gear_ratio'], float),
        rotor_inertia=np.asarray(act['rotor_inertia_kgm2'], float),
        torque_limit=np.asarray(act['torque_limit_nm'], float),
        friction=dict(d['friction']),
    )
