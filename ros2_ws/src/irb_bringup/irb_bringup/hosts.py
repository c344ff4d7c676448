"""Several "hosts" on one machine for tests and benchmarks: Linux network namespaces joined by
links (veth pairs, or TAP pairs through ``linkemu``) to one bridge, each link with an optional
delay and loss (tc netem where the kernel has it, ``linkemu`` otherwise). No ROS imports.

    with Cell() as cell:                      # needs root; ``unavailable()`` says why not
        ctrl = cell.add_host('ctrl')
        ws = cell.add_host('ws', delay_ms=5, loss=0.01)
        argv = cell.wrap(ws, ['ros2', 'run', ...])   # run a command on that host

Every host gets 10.<a>.<b>.<n>/24 on its link, loopback up and a multicast route (DDS
discovery with ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET multicasts over the bridge). Processes in
different namespaces still share /dev/shm: run DDS with ``fastdds_profile()`` (UDPv4 only) so
nothing crosses "hosts" by shared memory. ``close()`` removes namespaces, links, bridge and
emulators, also after a failure.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

_IP = 'ip'


def _run(*cmd: str, check: bool = True) -> subprocess.CompletedProcess:
    res = subprocess.run(list(cmd), capture_output=True, text=True, timeout=30)
    if check and res.returncode != 0:
        raise RuntimeError(f'{" ".join(cmd)}: {res.stderr.strip() or res.returncode}')
    return res


def unavailable() -> str | None:
    """Why namespaces cannot be made here (one line), or None when they can."""
    if sys.platform != 'linux':
        return 'network namespaces need Linux'
    if os.geteuid() != 0:
        return 'creating network namespaces needs root (CI runs as root)'
    if shutil.which(_IP) is None:
        return 'iproute2 (`ip`) is not installed (apt-get install iproute2)'
    probe = f'irbprobe{os.getpid()}'
    res = _run(_IP, 'netns', 'add', probe, check=False)
    if res.returncode != 0:
        return f'cannot create a network namespace: {res.stderr.strip()}'
    try:
        res = _run(_IP, 'link', 'add', f'{probe[:10]}br', 'type', 'bridge', check=False)
        if res.returncode != 0:
            return f'cannot create a bridge: {res.stderr.strip()}'
        _run(_IP, 'link', 'del', f'{probe[:10]}br', check=False)
        res = _run(_IP, '-n', probe, 'link', 'add', 'v0', 'type', 'veth', 'peer', 'name', 'v1',
                   check=False)
        if res.returncode != 0:
            return f'cannot create a veth pair: {res.stderr.strip()}'
    finally:
        _run(_IP, 'netns', 'del', probe, check=False)
    return None


_netem: bool | None = None


def netem_available() -> bool:
    """Whether tc's netem queue exists in this kernel (probed once in a scratch namespace)."""
    global _netem
    if _netem is None:
        probe = f'irbnetem{os.getpid()}'
        _netem = False
        if shutil.which('tc') and _run(_IP, 'netns', 'add', probe, check=False).returncode == 0:
            try:
                _run(_IP, '-n', probe, 'link', 'add', 'd0', 'type', 'dummy', check=False)
                _netem = _run('tc', '-n', probe, 'qdisc', 'add', 'dev', 'd0', 'root', 'netem',
                              'delay', '1ms', check=False).returncode == 0
            finally:
                _run(_IP, 'netns', 'del', probe, check=False)
    return _netem


def link_emulation() -> str | None:
    """How delayed or lossy links are made here: 'netem', 'linkemu' (TAP + user space) or
    None (neither: no netem and no /dev/net/tun)."""
    if netem_available():
        return 'netem'
    return 'linkemu' if os.path.exists('/dev/net/tun') else None


def fastdds_profile() -> Path:
    """The Fast DDS profile for several hosts (UDPv4 only, socket buffers for the 248 Hz
    topics): the installed share of irb_bringup, or the source tree."""
    try:
        from ament_index_python.packages import get_package_share_directory
        p = Path(get_package_share_directory('irb_bringup')) / 'config' / 'fastdds_hosts.xml'
        if p.exists():
            return p
    except Exception:  # noqa: BLE001 - not installed: the source tree
        pass
    return Path(__file__).resolve().parents[1] / 'config' / 'fastdds_hosts.xml'


def host_env(domain_id: int, profile: Path | None = None) -> dict:
    """Environment of a node on a host: SUBNET discovery, the UDP-only profile."""
    return {'ROS_DOMAIN_ID': str(domain_id), 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET',
            'ROS_STATIC_PEERS': '',
            'FASTRTPS_DEFAULT_PROFILES_FILE': str(profile or fastdds_profile())}


_ECHO = """
import socket, sys
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.bind(('0.0.0.0', int(sys.argv[1])))
print('ready', flush=True)
while True:
    data, peer = s.recvfrom(2048)
    s.sendto(data, peer)
"""
_PING = """
import socket, sys, time
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.settimeout(1.0)
out = []
for i in range(int(sys.argv[3])):
    t = time.perf_counter()
    s.sendto(str(i).encode(), (sys.argv[1], int(sys.argv[2])))
    try:
        while s.recvfrom(2048)[0] != str(i).encode():
            pass
        out.append((time.perf_counter() - t) * 1e3)
    except socket.timeout:
        pass
print(' '.join(f'{x:.3f}' for x in out))
"""


@dataclass
class Host:
    name: str
    netns: str
    ifname: str
    address: str
    delay_ms: float = 0.0
    loss: float = 0.0
    emulator: subprocess.Popen | None = field(default=None, repr=False)


class Cell:
    """A bridge and the hosts linked to it; a context manager that always cleans up."""

    def __init__(self, tag: str | None = None):
        self.tag = tag or f'{os.getpid() % 100000}'
        self.bridge = f'irb{self.tag}br'[:15]
        n = os.getpid()
        self.subnet = f'10.{200 + n % 50}.{(n // 50) % 250}'
        self.hosts: dict[str, Host] = {}
        self._up = False

    def __enter__(self) -> 'Cell':
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:
        why = unavailable()
        if why:
            raise RuntimeError(why)
        _run(_IP, 'link', 'add', self.bridge, 'type', 'bridge', 'mcast_snooping', '0')
        self._up = True
        _run(_IP, 'link', 'set', self.bridge, 'up')

    def add_host(self, name: str, delay_ms: float = 0.0, loss: float = 0.0,
                 emulate: bool = False) -> Host:
        """A namespace linked to the bridge; ``delay_ms`` and ``loss`` apply to each direction
        of its link: a message from host A to host B meets A's and B's link, so a round trip
        from a delayed host to an undelayed one takes 2 x delay_ms longer. ``emulate``: use
        the delaying link even at 0 ms and no loss (to measure what the emulation costs)."""
        i = len(self.hosts) + 1
        ns = f'irb{self.tag}_{name}'
        inner, outer = f'irb{self.tag}h{i}', f'irb{self.tag}b{i}'
        host = Host(name, ns, inner, f'{self.subnet}.{i + 1}', delay_ms, loss)
        self.hosts[name] = host
        _run(_IP, 'netns', 'add', ns)
        emulate = emulate or bool(delay_ms or loss)
        kind = link_emulation() if emulate else 'veth'
        if kind is None:
            raise RuntimeError('no way to delay a link here: tc netem missing and no '
                               '/dev/net/tun for the user-space link emulator')
        if kind == 'linkemu':
            host.emulator = subprocess.Popen(
                [sys.executable, '-m', 'irb_bringup.linkemu', '--a', inner, '--b', outer,
                 '--delay-ms', str(delay_ms), '--loss', str(loss), '--seed', str(i)],
                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                start_new_session=True)
            line = host.emulator.stdout.readline().strip()
            if line != 'ready':
                raise RuntimeError(f'link emulator for {name} did not start: {line}')
        else:
            _run(_IP, 'link', 'add', inner, 'type', 'veth', 'peer', 'name', outer)
        _run(_IP, 'link', 'set', inner, 'netns', ns)
        _run(_IP, 'link', 'set', outer, 'master', self.bridge)
        _run(_IP, 'link', 'set', outer, 'up')
        _run(_IP, '-n', ns, 'link', 'set', 'lo', 'up')
        _run(_IP, '-n', ns, 'addr', 'add', f'{host.address}/24', 'dev', inner)
        _run(_IP, '-n', ns, 'link', 'set', inner, 'up')
        _run(_IP, '-n', ns, 'route', 'add', '224.0.0.0/4', 'dev', inner)
        if kind == 'netem':
            spec = ['delay', f'{delay_ms}ms'] + (['loss', f'{100 * loss}%'] if loss else [])
            _run('tc', '-n', ns, 'qdisc', 'add', 'dev', inner, 'root', 'netem', *spec)
            _run('tc', 'qdisc', 'add', 'dev', outer, 'root', 'netem', *spec)
        return host

    def wrap(self, host: Host | str, argv) -> list[str]:
        """argv that runs ``argv`` on ``host`` (``ip netns exec`` execs it: same pid)."""
        h = self.hosts[host] if isinstance(host, str) else host
        return [_IP, 'netns', 'exec', h.netns, *argv]

    def udp_rtt_ms(self, src: str, dst: str, count: int = 20) -> list[float]:
        """Round-trip times [ms] of small UDP datagrams from ``src`` to an echo on ``dst``
        (plain sockets, no DDS: the link's own figure); lost ones are left out."""
        port = 47000 + os.getpid() % 1000
        echo = subprocess.Popen(self.wrap(dst, [sys.executable, '-c', _ECHO, str(port)]),
                                stdout=subprocess.PIPE, text=True, start_new_session=True)
        try:
            if echo.stdout.readline().strip() != 'ready':
                raise RuntimeError(f'UDP echo on {dst} did not start')
            res = _run(*self.wrap(src, [sys.executable, '-c', _PING, self.hosts[dst].address,
                                        str(port), str(count)]))
            return [float(x) for x in res.stdout.split()]
        finally:
            echo.kill()
            echo.wait(timeout=5)
            echo.stdout.close()

    def close(self) -> None:
        for h in self.hosts.values():
            if h.emulator is not None and h.emulator.poll() is None:
                h.emulator.terminate()
                try:
                    h.emulator.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    h.emulator.kill()
                    h.emulator.wait(timeout=5)
            if h.emulator is not None and h.emulator.stdout is not None:
                h.emulator.stdout.close()
            # processes still inside the namespace keep it alive: end them first
            pids = _run(_IP, 'netns', 'pids', h.netns, check=False).stdout.split()
            for pid in pids:
                try:
                    os.kill(int(pid), 9)
                except (ProcessLookupError, ValueError):
                    pass
            _run(_IP, 'netns', 'del', h.netns, check=False)
            _run(_IP, 'link', 'del', f'irb{self.tag}b{list(self.hosts).index(h.name) + 1}',
                 check=False)
        if self._up:
            _run(_IP, 'link', 'del', self.bridge, check=False)
            self._up = False
        self.hosts.clear()
