"""The Foxglove layout refers only to what the stack publishes, and its panel tree is whole."""
import json
import re

from irb_description.params import share_dir
from irb_description.state_publisher import SPEC

LAYOUT = share_dir() / 'config' / 'foxglove_layout.json'
# published by irb_control's simulator / axis_bridge (joint_states, electrical_power: 3 axes
# then total_none, total_shared, total_regenerative) and pdplus (torque_command: joints 1-3)
OTHERS = {'/joint_states': 6, '/torque_command': 3, '/electrical_power': 6}
SCRIPT_OUTPUT = '/studio_script/energy'


def _panels(node):
    if isinstance(node, str):
        return [node]
    return _panels(node['first']) + _panels(node['second'])


def test_layout_panels_and_topics():
    layout = json.loads(LAYOUT.read_text())
    panels = _panels(layout['layout'])
    assert sorted(panels) == sorted(layout['configById'])
    mine = {('/' + t.name.lstrip('/')) for t in SPEC.publishes}
    three_d = layout['configById']['3D!irb']
    assert three_d['layers']['robot']['topic'] == '/robot_description' in mine
    assert set(three_d['topics']) == {'/visualization/planned_path',
                                      '/visualization/tcp_trace'} <= mine
    assert three_d['followTfFrame'] == 'base_link'
    script = layout['userNodes']['energy']['sourceCode']
    assert f'export const output = "{SCRIPT_OUTPUT}"' in script
    for topic in re.findall(r'inputs = \[(.*?)\]', script)[0].replace('"', '').split(', '):
        assert topic in OTHERS
    seen = set()
    for pid in panels:
        for p in layout['configById'][pid].get('paths', []):
            m = re.fullmatch(r'(/[\w/]+)\.(\w+)(?:\[(\d+)\])?', p['value'])
            assert m, p['value']
            topic, _, index = m.groups()
            seen.add(topic)
            if topic == SCRIPT_OUTPUT:
                assert f'{m.group(2)}:' in script
            else:
                assert topic in OTHERS and int(index) < OTHERS[topic], p['value']
    assert seen == set(OTHERS) | {SCRIPT_OUTPUT}
