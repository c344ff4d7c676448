"""`ros2 run irb_control fake_axis_computer`: the simulator behind the axis-computer protocol.

The clock master: every period it sends a STATE packet to the bridge and waits for the answer
until the next cycle (logic in fake_axis_core.FakeAxisCore, protocol in doc/axis_protocol.md).
Faults (drop, delay, duplicate, reorder, corrupt, NaN) are injected with the given
probabilities; after ``miss_limit`` cycles without a command it holds on brakes and latches an
error until a command with reset = 1.
"""
from __future__ import annotations

import heapq
import json
import select
import socket
import time
from pathlib import Path

import numpy as np
from irb_description.model import RobotModel
from irb_description.node_help import NodeSpec, Param
from irb_description.node_main import declare_params, run_node, running
from rclpy.node import Node

from .fake_axis_core import FAULT_KINDS, FakeAxisCore, FaultConfig
from .plant import Plant, PlantConfig, default_plant_yaml, load_plant_friction


_d = PlantConfig()
SPEC = NodeSpec(
    'fake_axis_computer', 'irb_control',
    'The simulator behind the axis-computer UDP protocol, as the clock master: one STATE '
    'every period on the steady clock; applies only the COMMAND carrying the current '
    "cycle's sequence number; after miss_limit cycles without one it brakes and latches an "
    'error until a command with reset = 1. Fault injection on the outgoing states. No ROS '
    'topics (UDP only).',
    params=(
        Param('bridge_address', '127.0.0.1', '', "bridge's address for STATE packets"),
        Param('state_port', 6510, '', "bridge's UDP port for states"),
        Param('bind_address', '127.0.0.1', '', 'local address for COMMAND packets'),
        Param('command_port', 6511, '', 'local UDP port for commands'),
        Param('period_s', _d.period_s, 's', 'cycle period'),
        Param('miss_limit', 3, 'cycles', 'without a valid command: brakes, latched error'),
        Param('duration_s', 0.0, 's', 'stop after this long; 0 = never'),
        Param('stats_path', '', '', "write statistics JSON here at exit ('' = no)"),
        Param('initial_positions', list(_d.initial_q), 'rad', 'start pose of joints 1-3'),
        Param('seed', _d.seed, '', 'measurement noise seed'),
        Param('plant_friction_file', '', '', "plant friction YAML; '' = config/plant.yaml"),
        *(Param(f'fault_{k}', 0.0, '1/cycle', f'probability of a {k} fault per cycle')
          for k in FAULT_KINDS),
        Param('fault_delay_s', 0.006, 's', 'delay of a delayed state'),
        Param('fault_seed', 0, '', 'fault random seed'),
        Param('bound_controller_only', True, '', 'take commands only from the bridge address '
              'and its state port (the socket it sends commands from)')),
    example='ros2 run irb_control fake_axis_computer --ros-args -p fault_drop:=0.01')


class FakeAxisComputer(Node):
    """Parameters and logging; ``run()`` is the real-time loop on the steady clock."""

    def __init__(self, **kwargs):
        super().__init__('fake_axis_computer', **kwargs)
        P = declare_params(self, SPEC.params)
        self.bridge_address, self.state_port = P['bridge_address'], P['state_port']
        bind_address, command_port = P['bind_address'], P['command_port']
        self.period, miss_limit = P['period_s'], P['miss_limit']
        self.duration, self.stats_path = P['duration_s'], P['stats_path']
        initial, seed, ffile = P['initial_positions'], P['seed'], P['plant_friction_file']
        faults = {k: P[f'fault_{k}'] for k in FAULT_KINDS}
        delay_s, fault_seed = P['fault_delay_s'], P['fault_seed']
        model = RobotModel.load()
        _, friction = load_plant_friction(ffile or str(default_plant_yaml()), model.joint_names)
        # the axis core supervises the commands (miss_limit): the plant's own timeout is off
        plant = Plant(model, friction, PlantConfig(period_s=self.period,
                                                   initial_q=tuple(initial), seed=seed,
                                                   command_timeout_s=1e9))
        controller = ((self.bridge_address, self.state_port) if P['bound_controller_only']
                      else None)
        self.core = FakeAxisCore(plant, FaultConfig(**faults, delay_s=delay_s, seed=fault_seed),
                                 miss_limit, controller=controller)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((bind_address, command_port))
        self.sock.setblocking(False)
        self.latencies: list[float] = []
        active = {k: v for k, v in faults.items() if v > 0}
        self.get_logger().info(
            f'fake axis computer: states to {self.bridge_address}:{self.state_port}, commands '
            f'on {bind_address}:{command_port}, T = {self.period} s, miss limit {miss_limit}, '
            f'faults {active or "none"}')

    def _log_events(self) -> None:
        for e in self.core.events:
            self.get_logger().warn(e)
        self.core.events.clear()

    def run(self) -> None:
        """Real-time loop until shutdown or ``duration_s``."""
        t0 = time.monotonic()
        k = 0
        outbox: list[tuple[float, int, bytes]] = []   # (send time, tie-break, datagram)
        n = 0
        while running():
            t_cycle = t0 + k * self.period
            if self.duration > 0 and t_cycle - t0 >= self.duration:
                break
            for offset, data in self.core.begin_cycle():
                heapq.heappush(outbox, (t_cycle + offset, n, data))
                n += 1
            t_state_sent = None
            seq = self.core.seq
            t_next = t_cycle + self.period
            while True:
                now = time.monotonic()
                while outbox and outbox[0][0] <= now:
                    _, _, data = heapq.heappop(outbox)
                    self.sock.sendto(data, (self.bridge_address, self.state_port))
                    if t_state_sent is None:
                        t_state_sent = time.monotonic()
                if now >= t_next:
                    break
                wake = min(t_next, outbox[0][0]) if outbox else t_next
                ready, _, _ = select.select([self.sock], [], [], max(0.0, wake - now))
                if ready:
                    try:
                        data, source = self.sock.recvfrom(2048)
                    except BlockingIOError:
                        continue
                    if self.core.on_datagram(data, source) and t_state_sent is not None:
                        self.latencies.append(time.monotonic() - t_state_sent)
            self.core.end_cycle()
            self._log_events()
            if self.core.seq != seq:
                raise RuntimeError('sequence changed inside a cycle')
            k += 1
            behind = int((time.monotonic() - t0) / self.period) - k
            if behind > 0:                      # overran: skip the lost cycles, count them
                self.get_logger().warn(f'loop overran by {behind} cycles',
                                       throttle_duration_sec=1.0)
                for _ in range(behind):
                    self.core.begin_cycle()
                    self.core.end_cycle()
                k += behind

    def statistics(self) -> dict:
        lat = np.array(self.latencies) * 1e3
        cycles = self.core.seq
        return {
            'cycles': cycles, 'answered': int(lat.size), 'missed': self.core.missed_total,
            'missed_fraction': self.core.missed_total / max(cycles, 1),
            'latency_ms': ({'p50': float(np.percentile(lat, 50)),
                            'p99': float(np.percentile(lat, 99)), 'max': float(lat.max())}
                           if lat.size else None),
            'error': self.core.error, 'injected': dict(self.core.injected),
            'rejected': dict(self.core.rejected)}

    def destroy_node(self):
        stats = self.statistics()
        self.get_logger().info(f'statistics: {json.dumps(stats)}')
        if self.stats_path:
            Path(self.stats_path).write_text(json.dumps(stats, indent=2))
        self.sock.close()
        return super().destroy_node()


def main(args=None):
    run_node(FakeAxisComputer, lambda node: node.run(), args, spec=SPEC)


if __name__ == '__main__':
    main()
