"""Writes doc/example_log.csv.gz: a friction log as another robot's controller might export it
(time [s] irregular by 1-13 ms, position [rad], velocity [rad/s], friction torque [N m]) of one
joint named ``Achse 2`` moving continuously (no constant-speed holds). Known friction: offset
0.12 N m, Coulomb 1.1 (v > 0) / 0.9 (v < 0) N m, static 1.6 N m at v_s 0.05 rad/s, viscous 0.8
N m s/rad; noise 0.03 N m, 0.3 % spikes."""
import gzip
from pathlib import Path

import numpy as np

rng = np.random.default_rng(3)
n = 8000
t = 5.0 + np.cumsum(rng.uniform(1e-3, 13e-3, n))
v = (0.5 * np.sin(2 * np.pi * 0.07 * t) + 0.25 * np.sin(2 * np.pi * 0.23 * t + 1)
     + 0.08 * np.sin(2 * np.pi * 0.6 * t + 2))
q = np.cumsum(v * np.diff(t, prepend=t[0]))
e = np.exp(-(v / 0.05) ** 2)
tau = 0.12 + 0.8 * v + np.where(v > 0, 1.1 * (1 - e) + 1.6 * e, -(0.9 * (1 - e) + 1.6 * e))
tau += 0.03 * rng.standard_normal(n)
spikes = rng.random(n) < 0.003
tau[spikes] += 3 * rng.standard_normal(spikes.sum())
with gzip.open(Path(__file__).with_name('example_log.csv.gz'), 'wt') as f:
    f.write('time,pos_2,vel_2,tf_2\n')
    for row in zip(t, q, v + 0.001 * rng.standard_normal(n), tau):
        f.write(','.join(f'{x:.9g}' for x in row) + '\n')
