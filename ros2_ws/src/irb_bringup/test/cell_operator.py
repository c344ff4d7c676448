"""The operator's workstation in the multi-host test: asks the planner for the thesis circle,
waits for pdplus's verdict, enables pdplus and watches the motion to its end (all through
irb_bringup.thesis_run.Link, the main job's own client). One JSON line per command read from
stdin ('plan', 'enable', 'start', 'wait_end', 'quit'); run on a host with `ip netns exec`."""
import json
import sys

from irb_bringup.thesis_run import Link

CIRCLE = {'center_m': [0.6, 0.0, 0.13], 'radius_m': 0.15, 'circle_duration_s': 6.0,
          'planner_grid': 80}
MODE_PATH, MODE_STOPPED, MODE_HOLD = 2, 4, 5


def say(**kw):
    print(json.dumps(kw), flush=True)


def enable(link):
    """Across hosts pdplus may not have the simulator's (latched) axis status yet when asked:
    it refuses with "no axis status yet"; ask again (bounded) once it has."""
    for _ in range(100):
        try:
            return link.enable(None)
        except RuntimeError as exc:
            if 'no axis status yet' not in str(exc):
                raise
            link.spin_until(lambda: False, 0.3)
    link.enable(None)


def main():
    link = Link()
    try:
        for line in sys.stdin:
            cmd = line.strip()
            if cmd == 'plan':
                def verdicts():
                    st = link.plan_status
                    return st.accepted_count + st.refused_count if st is not None else 0
                before = verdicts()
                resp = link.plan(CIRCLE, 'energy', '', None)
                ok = link.spin_until(lambda: verdicts() > before, 60)
                st = link.plan_status
                say(step='plan', points=len(resp.trajectory.points), duration=resp.duration,
                    verdict=ok, accepted=bool(ok and st.accepted), reason=st.reason if ok else '')
            elif cmd == 'enable':
                enable(link)
                done = link.spin_until(lambda: MODE_PATH in link.modes
                                       and link.modes[-1] in (MODE_STOPPED, MODE_HOLD), 60)
                say(step='enable', done=done, modes=link.modes, stop_reason=link.stop_reason)
            elif cmd == 'start':            # enable, answer once the path is running
                enable(link)
                ok = link.spin_until(lambda: MODE_PATH in link.modes, 60)
                say(step='start', moving=ok, modes=link.modes)
            elif cmd == 'wait_end':
                done = link.spin_until(lambda: link.modes[-1] in (MODE_STOPPED, MODE_HOLD), 60)
                say(step='wait_end', done=done, modes=link.modes, stop_reason=link.stop_reason)
            elif cmd == 'quit':
                break
    except Exception as exc:  # noqa: BLE001 - one line for the test to show
        say(step='error', error=f'{type(exc).__name__}: {exc}')
    finally:
        link.close()


if __name__ == '__main__':
    main()
