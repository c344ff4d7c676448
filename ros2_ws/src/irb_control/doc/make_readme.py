#!/usr/bin/env python3
"""Write the package README from ``README.tmpl.md``: ``{{params:NODE}}``, ``{{topics:NODE}}``
and ``{{summary:NODE}}`` become the node's parameter table (``param_table_md``), topic and
service table and summary, from its ``SPEC`` (the same data ``--help`` prints).

    python ros2_ws/src/irb_control/doc/make_readme.py      # after changing a SPEC
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def specs() -> dict:
    from irb_control import (axis_bridge_node, fake_axis_computer_node, pdplus_node,
                             simulator_node)
    return {m.SPEC.executable: m.SPEC for m in (simulator_node, pdplus_node, axis_bridge_node,
                                                fake_axis_computer_node)}


def topic_table(spec) -> str:
    rows = ['| topic / service | type | direction, meaning |', '|---|---|---|']
    for kind, items in (('in', spec.subscribes), ('out', spec.publishes),
                        ('service', spec.services)):
        for t in items:
            rows.append(f'| `{t.name}` | `{t.type}` | {kind}: {t.description} |')
    return '\n'.join(rows)


def render(template: str) -> str:
    from irb_description.node_help import param_table_md
    sp = specs()

    def sub(m):
        what, node = m.group(1), m.group(2)
        s = sp[node]
        return {'params': param_table_md, 'topics': topic_table,
                'summary': lambda x: x.summary}[what](s)
    return re.sub(r'\{\{(params|topics|summary):(\w+)\}\}', sub, template)


def main() -> int:
    text = render((HERE / 'README.tmpl.md').read_text())
    (HERE.parent / 'README.md').write_text(text)
    print(f'README.md: {len(text.splitlines())} lines')
    return 0


if __name__ == '__main__':
    sys.exit(main())
