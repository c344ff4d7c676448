"""PathSpec <-> request <-> YAML path file for every path type (issue 18), and the plan
client's --path-file refusing bad files with one line."""
import numpy as np
import pytest
import yaml
from irb_description.path import path_from_spec, path_spec, rectangle_path
from irb_interfaces.srv import PlanPath

from irb_planning.messages import path_msg, path_msg_from_spec, request_from_msg
from irb_planning.plan_cli import build_request, main, parse_args, read_path_file
from irb_planning.planner import request_path
from irb_planning.request import validate

SPECS = [
    dict(type='circle', center=[0.6, 0.0, 0.13], radius=0.15, start_angle=0.0, direction=1),
    dict(type='arc', center=[0.65, 0.0, 0.3], normal=[0.2, -0.4, 1.0], radius=0.12,
         start_angle=0.4, sweep=-4.5),
    dict(type='line', waypoints=[[0.5, -0.2, 0.25], [0.8, 0.25, 0.45]]),
    path_spec(rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025)),
    dict(type='spline', waypoints=[[0.55, -0.25, 0.25], [0.8, -0.2, 0.3], [0.85, 0.05, 0.4]],
         closed=False),
]


@pytest.mark.parametrize('spec', SPECS, ids=[s['type'] for s in SPECS])
def test_yaml_to_message_to_request_is_the_same_path(tmp_path, spec):
    f = tmp_path / 'p.yaml'
    f.write_text(yaml.safe_dump(spec))
    msg = read_path_file(str(f))
    req = PlanPath.Request(path=msg, objective='energy', duration=5.0)
    r = validate(request_from_msg(req), 60)
    th = np.linspace(0, 2 * np.pi, 101)
    np.testing.assert_allclose(request_path(r).point(th), path_from_spec(spec).point(th),
                               atol=1e-15)
    # and back: the request's PathSpec gives the same request
    again = validate(request_from_msg(PlanPath.Request(path=path_msg(r), objective='energy',
                                                       duration=5.0)), 60)
    assert again.path_key == r.path_key
    a = parse_args(['--path-file', str(f), '--duration', '5'])
    assert build_request(a).path.type == spec['type']


def test_an_old_circle_message_still_plans_the_circle():
    req = PlanPath.Request(objective='energy', duration=5.0)
    req.path.center.x, req.path.radius, req.path.direction = 0.6, 0.15, 1   # type '' (old)
    r = validate(request_from_msg(req), 60)
    assert r.path_type == 'circle' and type(request_path(r)).__name__ == 'CirclePath'


@pytest.mark.parametrize('text, words', [
    ('type: polyline\nwaypoints: [[0.5, 0, 0.3], [0.7, 0, 0.3], [0.7, 0.01, 0.3]]\n'
     'blend_radii: [0.05]\n', 'overlap'),
    ('type: [unclosed\n', 'not YAML'),
    ('type: hexagon\n', 'unknown path type'),
    ('- 1\n- 2\n', 'mapping'),
])
def test_bad_path_files_are_refused_with_one_line(tmp_path, capsys, text, words):
    f = tmp_path / 'bad.yaml'
    f.write_text(text)
    assert main(['plan', '--path-file', str(f)]) == 1
    err = capsys.readouterr().err
    assert words in err and err.count('\n') == 1 and 'Traceback' not in err


def test_missing_path_file(capsys):
    assert main(['plan', '--path-file', '/nonexistent/x.yaml']) == 1
    assert 'cannot read path file' in capsys.readouterr().err


def test_path_msg_from_spec_rejects_what_the_planner_would(tmp_path):
    with pytest.raises(ValueError, match='turns back'):
        path_msg_from_spec(dict(type='polyline', waypoints=[[0.5, 0, 0.3], [0.7, 0, 0.3],
                                                             [0.5, 0, 0.3]], blend_radii=[0.01]))
