"""The gyroscope's attitude maths, written once in CasADi: imu_tk's quaternion RK4 step and its residual.

The gyroscope's map from raw to calibrated rate is its sensor description (imucal.model.gyroscope:
named parameters, omega = M_g^-1 (B_g^-1 (raw_g - s_g) - G_s a)). The attitude over a motion segment
is integrated with imu_tk's quaternion RK4 step (Tedaldi 2014, rate sampled at both ends and linearly
interpolated at the midpoint), normalised after each step (imucal.gyro.attitude multiplies the steps).
"""
from __future__ import annotations

import casadi as ca

from imucal.model.channels import Channel
from imucal.model.gyroscope import (AXES, MIS_NAMES, gyro_model, misalignment_entries,  # noqa: F401
                                    misalignment_matrix)

#: the channels the gyroscope reads: its rate, the calibrated specific force (gravity directions,
#: g-sensitivity) and the time base it integrates over (its description's)
READS: tuple[Channel, ...] = gyro_model().reads


def _omega_matrix(w):
    """4x4 matrix of q' = 0.5 Omega(w) q for q = (w, x, y, z) and a body rate w (imu_tk's order)."""
    return ca.vertcat(ca.horzcat(0, -w[0], -w[1], -w[2]),
                      ca.horzcat(w[0], 0, w[2], -w[1]),
                      ca.horzcat(w[1], -w[2], 0, w[0]),
                      ca.horzcat(w[2], w[1], -w[0], 0))


def rk4_matrix() -> ca.Function:
    """imu_tk's quaternion RK4 step as a linear map: (w0, w1, dt) -> A with q_next = A q before normalising.

    q' = 0.5 Omega(w) q is linear in q, so each RK4 stage is a matrix times q (Tedaldi 2014, Eq. 9;
    rate at both ends, linear interpolation at the midpoint): k_i = K_i q.
    """
    w0, w1, dt = ca.SX.sym("w0", 3), ca.SX.sym("w1", 3), ca.SX.sym("dt")
    eye = ca.SX.eye(4)
    wm = 0.5 * (w0 + w1)
    K1 = 0.5 * _omega_matrix(w0)
    K2 = 0.5 * ca.mtimes(_omega_matrix(wm), eye + 0.5 * dt * K1)
    K3 = 0.5 * ca.mtimes(_omega_matrix(wm), eye + 0.5 * dt * K2)
    K4 = 0.5 * ca.mtimes(_omega_matrix(w1), eye + dt * K3)
    return ca.Function("gyro_rk4_matrix", [w0, w1, dt], [eye + dt * (K1 + 2 * K2 + 2 * K3 + K4) / 6])


def rk4_step() -> ca.Function:
    """One quaternion RK4 step (q, [w0; w1; dt; reset]) -> q; reset = 1 restarts from identity."""
    q0 = ca.SX.sym("q0", 4)
    u = ca.SX.sym("u", 8)
    w0, w1, dt, reset = u[0:3], u[3:6], u[6], u[7]
    q = reset * ca.DM([1, 0, 0, 0]) + (1 - reset) * q0  # branch-free restart at a segment's first step
    qn = ca.mtimes(rk4_matrix()(w0, w1, dt), q)
    return ca.Function("gyro_rk4", [q0, u], [qn / ca.norm_2(qn)])


def rk4_increment() -> ca.Function:
    """The unit quaternion a of one RK4 step, (w0, w1, dt) -> a with normalise(A q) = q (x) a.

    Omega(w) q = q (x) (0, w) (a body rate right-multiplies), so every RK4 stage, and A itself,
    right-multiplies q by a fixed quaternion: A q = q (x) (A e), e = (1, 0, 0, 0). For a unit q,
    |q (x) a| = |a|, so imu_tk's normalised step is q (x) a / |a| exactly.
    """
    w0, w1, dt = ca.SX.sym("w0", 3), ca.SX.sym("w1", 3), ca.SX.sym("dt")
    a = ca.mtimes(rk4_matrix()(w0, w1, dt), ca.DM([1, 0, 0, 0]))
    return ca.Function("gyro_rk4_increment", [w0, w1, dt], [a / ca.norm_2(a)])


def quat_mul(p, q):
    """Hamilton product p (x) q of quaternions (w, x, y, z)."""
    return ca.vertcat(p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
                      p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
                      p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
                      p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0])


def quat_to_rot(q):
    """Rotation matrix (body to start frame) of a unit quaternion q = (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def direction_residual() -> ca.Function:
    """imu_tk's MultiPosGyroResidual: R^T u0 - u1 (gravity at the start, carried to the end)."""
    q = ca.SX.sym("q", 4)
    u0 = ca.SX.sym("u0", 3)
    u1 = ca.SX.sym("u1", 3)
    return ca.Function("gyro_dir_res", [q, u0, u1], [ca.mtimes(quat_to_rot(q).T, u0) - u1])
