"""Dynamics: CasADi RNEA vs pinocchio, inertias, the model's use of Table 3.3."""
import casadi as ca
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from irb_description.casadi_dynamics import rnea_function
from irb_description.dh import dh_matrix
from irb_description.model_check import inertia_problems
from irb_description.params import box_inertia


def test_casadi_rnea_equals_pinocchio_rnea(model, rng):
    f = rnea_function(model)
    for _ in range(100):
        q = rng.uniform(model.limits.lower, model.limits.upper)
        qd = rng.uniform(-3, 3, 3)
        qdd = rng.uniform(-10, 10, 3)
        ref = pin.rnea(model.model, model.model.createData(), q, qd, qdd)
        assert np.abs(np.asarray(f(q, qd, qdd)).ravel() - ref).max() <= 1e-9


def test_batched_rnea_equals_rnea_row_by_row(model, rng):
    # the plan check and identification evaluate (M, 3) arrays with inverse_dynamics_batch
    # (5000 rows: across its chunks of RNEA_CHUNK_ROWS)
    q = rng.uniform(model.limits.lower, model.limits.upper, (5000, 3))
    qd, qdd = rng.uniform(-3, 3, (5000, 3)), rng.uniform(-10, 10, (5000, 3))
    rows = np.array([model.inverse_dynamics(a, b, c) for a, b, c in zip(q, qd, qdd)])
    assert np.array_equal(model.inverse_dynamics_batch(q, qd, qdd), rows)
    assert np.array_equal(model.inverse_dynamics_batch(q[:1], qd[:1], qdd[:1]), rows[:1])
    assert model.inverse_dynamics_batch(q[:0], qd[:0], qdd[:0]).shape == (0, 3)
    # a model changed after load (identification's perturbed copies) is the one evaluated
    other = model.copy()
    other.model.inertias[2].mass *= 1.5
    assert not np.allclose(other.inverse_dynamics_batch(q, qd, qdd), rows)


def test_casadi_rnea_is_differentiable(model):
    q, qd, qdd = (ca.SX.sym(n, 3) for n in ('q', 'qd', 'qdd'))
    tau = rnea_function(model)(q, qd, qdd)
    dM = ca.Function('M', [q], [ca.jacobian(tau, qdd)])
    q0 = np.array([0.2, 0.5, 0.3])
    assert_allclose(np.asarray(dM(q0)), model.mass_matrix(q0), atol=1e-9)


def test_robot_equation_pieces_are_consistent(model, rng):
    for _ in range(30):
        q = rng.uniform(-1, 1, 3)
        qd = rng.uniform(-2, 2, 3)
        qdd = rng.uniform(-5, 5, 3)
        M = model.mass_matrix(q)
        assert_allclose(M, M.T, atol=1e-12)
        assert np.linalg.eigvalsh(M).min() > 0
        tau = model.inverse_dynamics(q, qd, qdd)
        assert_allclose(tau, M @ qdd + model.coriolis(q, qd) + model.gravity(q), atol=1e-9)
        assert_allclose(model.coriolis_matrix(q, qd) @ qd, model.coriolis(q, qd), atol=1e-9)
        assert_allclose(model.forward_dynamics(q, qd, tau), qdd, atol=1e-8)


def test_gravity_does_not_load_joint_1(model, rng):
    for _ in range(10):
        assert abs(model.gravity(rng.uniform(-1, 1, 3))[0]) < 1e-9


def test_every_inertia_is_physical(model):
    for link in model.dynamics.links:
        assert inertia_problems(link.name, link.inertia) == []
        ev = np.sort(np.linalg.eigvalsh(link.inertia))
        assert ev[0] > 0 and ev[0] + ev[1] >= ev[2]
    # also the merged bodies pinocchio uses
    for i in range(1, model.nq + 1):
        assert inertia_problems(model.model.names[i], model.model.inertias[i].inertia) == []


def test_inertia_problems_catches_bad_tensors():
    assert inertia_problems('x', np.diag([1.0, 1.0, 3.0]))      # triangle inequality
    assert inertia_problems('x', np.diag([1.0, -1.0, 1.0]))     # not positive definite
    assert inertia_problems('x', np.array([[1, 0.5, 0], [0, 1, 0], [0, 0, 1.0]]))


def test_box_inertia_formula():
    I = box_inertia(12.0, [1.0, 2.0, 3.0])
    assert_allclose(np.diag(I), [13.0, 10.0, 5.0])


def test_reduced_model_carries_table_3_3_masses_and_coms(model):
    for i, link in enumerate(model.dynamics.links, start=1):
        inertia = model.model.inertias[i]
        assert inertia.mass == pytest.approx(link.mass, rel=1e-12)
        assert_allclose(inertia.lever, link.com, atol=1e-12)
        assert_allclose(inertia.inertia, link.inertia, atol=1e-12)
    assert [lk.mass for lk in model.dynamics.links] == [104.3933, 20.4521, 50.5887]


@pytest.mark.parametrize('link_index', [1, 2])   # links 2 and 3-6 (0-based 1, 2)
def test_com_conversion_from_dh_frames(model, rng, link_index):
    """Table 3.3: CoM measured from the origin of frame i-1, in the axes of frame i."""
    import yaml
    from irb_description.params import config_path
    table = yaml.safe_load(config_path('dynamics.yaml').read_text())
    name = model.dynamics.links[link_index].name
    com_dh = np.asarray(table['links'][name]['com_dh_mm']) / 1000.0
    k = model.kinematics
    for _ in range(10):
        q = rng.uniform(-1, 1, 3)
        q6 = np.concatenate([q, np.zeros(3)])
        T_prev = np.eye(4)
        for j in range(link_index):
            T_prev = T_prev @ dh_matrix(q6[j] + k.dh_offset[j], k.dh_d[j], k.dh_a[j],
                                        k.dh_alpha[j])
        T_i = T_prev @ dh_matrix(q6[link_index] + k.dh_offset[link_index],
                                 k.dh_d[link_index], k.dh_a[link_index], k.dh_alpha[link_index])
        com_world_dh = T_prev[:3, 3] + T_i[:3, :3] @ com_dh
        data = model.model.createData()
        pin.forwardKinematics(model.model, data, q)
        j = link_index + 1
        com_world_urdf = data.oMi[j].act(model.model.inertias[j].lever)
        assert_allclose(com_world_urdf, com_world_dh, atol=1e-9)
