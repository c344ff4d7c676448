"""The workspace's package layout: dependencies run one way and are declared, nothing reaches
into another package's private names (read from the sources with ast, nothing imported)."""
import ast
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2]
PYTHON_PACKAGES = ['irb_description', 'irb_control', 'irb_planning', 'irb_identification',
                   'irb_bringup']
# which workspace packages each package may import (design: description <- control, planning;
# identification -> control only for the plant and closed loop of its re-simulations;
# bringup -> all; nothing -> bringup)
ALLOWED = {
    'irb_description': {'irb_interfaces'},
    'irb_control': {'irb_interfaces', 'irb_description'},
    'irb_planning': {'irb_interfaces', 'irb_description'},
    'irb_identification': {'irb_interfaces', 'irb_description', 'irb_control'},
    'irb_bringup': {'irb_interfaces', 'irb_description', 'irb_control', 'irb_planning',
                    'irb_identification'},
}
# the irb_control modules identification may use: the plant and the closed loop it re-simulates
IDENTIFICATION_CONTROL_MODULES = {'plant', 'plant_effects', 'closed_loop', 'pd_plus',
                                  'profiles'}
WORKSPACE = set(PYTHON_PACKAGES) | {'irb_interfaces'}


def imports(pkg: str):
    """(file, module, names) of every import of a workspace package in ``pkg``'s Python files
    (package, tests, benchmarks, launch files)."""
    for f in sorted((SRC / pkg).rglob('*.py')):
        tree = ast.parse(f.read_text(), str(f))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                if node.module.split('.')[0] in WORKSPACE:
                    yield f, node.module, [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.split('.')[0] in WORKSPACE:
                        yield f, a.name, []
            elif (isinstance(node, ast.Call) and getattr(node.func, 'attr', '') == 'importorskip'
                  and node.args and isinstance(node.args[0], ast.Constant)
                  and str(node.args[0].value).split('.')[0] in WORKSPACE):
                yield f, str(node.args[0].value), []


def declared(pkg: str) -> set[str]:
    root = ET.parse(SRC / pkg / 'package.xml').getroot()
    return {e.text.strip() for e in root if e.tag.endswith('depend') and e.text}


@pytest.mark.parametrize('pkg', PYTHON_PACKAGES)
def test_dependencies_run_one_way_and_are_declared(pkg):
    deps = declared(pkg)
    wrong = []
    for f, module, _ in imports(pkg):
        other = module.split('.')[0]
        if other == pkg:
            continue
        where = f'{f.relative_to(SRC)}: {module}'
        if other not in ALLOWED[pkg]:
            wrong.append(f'{where} (not allowed for {pkg})')
        elif other not in deps:
            wrong.append(f'{where} ({other} not declared in package.xml)')
        elif pkg == 'irb_identification' and other == 'irb_control':
            sub = module.split('.')[1] if '.' in module else ''
            if sub not in IDENTIFICATION_CONTROL_MODULES:
                wrong.append(f'{where} (identification uses irb_control only for the plant)')
    assert not wrong, '\n'.join(wrong)


@pytest.mark.parametrize('pkg', PYTHON_PACKAGES)
def test_no_private_names_of_other_packages(pkg):
    wrong = [f'{f.relative_to(SRC)}: {module} {names}' for f, module, names in imports(pkg)
             if module.split('.')[0] != pkg
             and (any(n.startswith('_') for n in names)
                  or any(p.startswith('_') for p in module.split('.')[1:]))]
    assert not wrong, '\n'.join(wrong)


def test_nothing_depends_on_bringup():
    users = [p for p in PYTHON_PACKAGES + ['irb_interfaces']
             if p != 'irb_bringup' and 'irb_bringup' in declared(p)]
    assert not users
    assert all(module.split('.')[0] != 'irb_bringup'
               for p in PYTHON_PACKAGES if p != 'irb_bringup' for _, module, _ in imports(p))
