"""Six-joint dynamics (six_axis_dynamics): CasADi = pinocchio, the three-axis model unchanged
when joints 4-6 are locked, the wrist's masses where the kinematics put them."""
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from irb_description.six_axis import SixAxisKinematics
from irb_description.six_axis_dynamics import (Body, SixAxisDynamics, is_physical,
                                               load_wrist)
from irb_description.params import box_inertia

G = 9.81


@pytest.fixture(scope='module')
def dyn():
    return SixAxisDynamics()


def random_state(rng, dyn):
    q = rng.uniform(dyn.lower, dyn.upper)
    return q, rng.uniform(-3.0, 3.0, 6), rng.uniform(-10.0, 10.0, 6)


def test_casadi_rnea_equals_pinocchio_on_six_joints(dyn, rng):
    f = dyn.rnea_function()
    for _ in range(50):
        q, qd, qdd = random_state(rng, dyn)
        tau_ca = np.asarray(f(q, qd, qdd), float).ravel()
        assert np.abs(tau_ca - dyn.inverse_dynamics(q, qd, qdd)).max() <= 1e-9


def test_locking_joints_4_to_6_reproduces_the_three_axis_model(model, dyn, rng):
    reduced = dyn.three_axis_model()
    data = reduced.createData()
    for _ in range(100):
        q, qd, qdd = (rng.uniform(-2.0, 2.0, 3) for _ in range(3))
        tau3 = model.inverse_dynamics(q, qd, qdd)
        assert np.abs(pin.rnea(reduced, data, q, qd, qdd) - tau3).max() <= 1e-9
        # the six-joint model itself, wrist at rest at 0: the same first three torques
        z = np.zeros(3)
        tau6 = dyn.inverse_dynamics(np.r_[q, z], np.r_[qd, z], np.r_[qdd, z])
        assert np.abs(tau6[:3] - tau3).max() <= 1e-9
    assert dyn.total_mass() == pytest.approx(sum(lk.mass for lk in model.dynamics.links),
                                             rel=1e-12)


def test_the_wrist_bodies_are_the_yaml_assumptions_and_the_forearm_is_a_rigid_body(dyn):
    wrist, payload = load_wrist()
    for n in ('link_4', 'link_5', 'link_6'):
        inertia = dyn.model.inertias[dyn.model.getJointId(f'joint_{n[-1]}')]
        assert inertia.mass == pytest.approx(wrist[n].mass, rel=1e-12)
        assert_allclose(inertia.lever, wrist[n].com, atol=1e-12)
        assert is_physical(inertia)
    assert payload.mass == 0.0      # the thesis's model carries no payload
    assert is_physical(dyn.forearm)
    assert 0.0 < dyn.forearm.mass < 50.5887


def test_gravity_is_the_gradient_of_the_potential_energy(model, dyn, rng):
    """Independent of pinocchio: V(q) = sum m g z_com with the CoMs placed by six_axis's
    numpy forward kinematics; g(q) = dV/dq by central differences."""
    kin = SixAxisKinematics(model.kinematics)
    bodies = [dyn.model.inertias[i] for i in range(1, 7)]

    def V(q):
        T = kin.link_poses(q)
        return sum(b.mass * G * (T[i][0, :3, :3] @ b.lever + T[i][0, :3, 3])[2]
                   for i, b in enumerate(bodies))
    h = 1e-6
    for _ in range(10):
        q = rng.uniform(dyn.lower, dyn.upper)
        grad = np.array([(V(q + h * e) - V(q - h * e)) / (2 * h) for e in np.eye(6)])
        assert_allclose(dyn.gravity(q), grad, atol=1e-5)


def test_kinetic_energy_is_half_qd_m_qd(model, dyn, rng):
    """Independent of pinocchio: each body's velocity and angular velocity from six_axis's
    numpy FK by central differences along qd, 1/2 sum (m |v_c|^2 + w^T R I R^T w), against
    1/2 qd^T M(q) qd (masses, CoMs and rotational inertias of the wrist all enter)."""
    kin = SixAxisKinematics(model.kinematics)
    bodies = [dyn.model.inertias[i] for i in range(1, 7)]
    eps = 1e-6
    for _ in range(10):
        q = rng.uniform(dyn.lower, dyn.upper)
        qd = rng.uniform(-2.0, 2.0, 6)
        Tp, Tm, T0 = kin.link_poses(q + eps * qd), kin.link_poses(q - eps * qd), \
            kin.link_poses(q)
        ke = 0.0
        for i, b in enumerate(bodies):
            R, Rp, Rm = T0[i][0, :3, :3], Tp[i][0, :3, :3], Tm[i][0, :3, :3]
            c = (Tp[i][0, :3, 3] + Rp @ b.lever - Tm[i][0, :3, 3] - Rm @ b.lever) / (2 * eps)
            W = (Rp - Rm) / (2 * eps) @ R.T
            w = np.array([W[2, 1], W[0, 2], W[1, 0]])
            ke += 0.5 * (b.mass * c @ c + w @ R @ np.asarray(b.inertia) @ R.T @ w)
        M = dyn.mass_matrix(q)
        assert 0.5 * qd @ M @ qd == pytest.approx(ke, rel=1e-7)
        assert np.all(np.linalg.eigvalsh(M) > 0)


def test_a_payload_on_tool0_loads_the_wrist(model):
    """6 kg 0.1 m out of the flange, forearm horizontal and the tool pointing down
    (q5 = 90 deg): the load hangs 0.6 m ahead of axes 2 and 3 and right below axes 4, 5, 6, so
    g(q) grows by -m g 0.6 on joints 2 and 3 (dV/dq: tilting forward lowers it) only."""
    wrist, _ = load_wrist()
    m = 6.0
    pay = Body(m, np.array([0.0, 0.0, 0.1]), box_inertia(m, [0.05, 0.05, 0.05]))
    loaded = SixAxisDynamics(wrist=wrist, payload=pay)
    bare = SixAxisDynamics(wrist=wrist)
    q = np.array([0.0, 0.0, 0.0, 0.0, np.pi / 2, 0.0])
    dg = loaded.gravity(q) - bare.gravity(q)
    # 1e-8: the URDF writes tool0's pitch pi/2 with 10 digits (2e-10 rad off), which tilts
    # the load's 0.165 m lever below axis 5 by 3e-11 m: 1.2e-9 N m on joint 5
    assert_allclose(dg, [0.0, -m * G * 0.6, -m * G * 0.6, 0.0, 0.0, 0.0], atol=1e-8)
    assert loaded.total_mass() == pytest.approx(bare.total_mass() + m, rel=1e-12)
