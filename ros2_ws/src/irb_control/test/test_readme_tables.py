"""The README's parameter and topic tables are the nodes' SPECs (the data --help prints and
the nodes declare): regenerated from doc/README.tmpl.md they give the README as it is."""
import importlib.util
from pathlib import Path

import pytest

pytest.importorskip('rclpy')
PKG = Path(__file__).resolve().parents[1]


def _make_readme():
    spec = importlib.util.spec_from_file_location('make_readme', PKG / 'doc' / 'make_readme.py')
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_readme_is_made_from_the_specs():
    from irb_description.node_help import param_table_md
    mr = _make_readme()
    readme = (PKG / 'README.md').read_text()
    assert mr.render((PKG / 'doc' / 'README.tmpl.md').read_text()) == readme, \
        'README.md is stale: run python ros2_ws/src/irb_control/doc/make_readme.py'
    for name, spec in mr.specs().items():
        assert param_table_md(spec) in readme, name
    assert len(readme.splitlines()) <= 300
