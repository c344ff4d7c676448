"""`ros2 run irb_description generate_urdf [--check] [--output PATH]`: write the URDF from YAML.

Without arguments rewrites urdf/irb1600_6_12.urdf in the description package; --check only
compares and exits 1 when the file is out of date.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .params import load_dynamics, load_kinematics, urdf_path
from .urdf_gen import generate_urdf


def main(args=None) -> int:
    parser = argparse.ArgumentParser(
        prog='ros2 run irb_description generate_urdf',
        description='Write urdf/irb1600_6_12.urdf of the description package from '
        'config/kinematics.yaml and config/dynamics.yaml; --check only compares and exits 1 '
        'when the file is out of date.',
        epilog='example: ros2 run irb_description generate_urdf --check')
    parser.add_argument('--output', type=Path, default=None, help='URDF path to write')
    parser.add_argument('--check', action='store_true', help='compare only, exit 1 if stale')
    ns = parser.parse_args(args)
    text = generate_urdf(load_kinematics(), load_dynamics())
    target = ns.output or urdf_path()
    if ns.check:
        current = target.read_text() if target.is_file() else ''
        if current != text:
            print(f'{target} is out of date: run `ros2 run irb_description generate_urdf`',
                  file=sys.stderr)
            return 1
        print(f'{target} is up to date')
        return 0
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(text)
    print(f'wrote {target}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
