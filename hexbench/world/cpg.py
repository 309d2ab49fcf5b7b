"""Hopf-oscillator central pattern generator (paper section 2.2, eqs 1-4). Pure numpy.

Six coupled Hopf oscillators, one per leg in the order RF, RM, RB, LB, LM, LF (eq. 3):

    dx_i = alpha (mu - x_i^2 - y_i^2) x_i - omega_i y_i
    dy_i = alpha (mu - x_i^2 - y_i^2) y_i + omega_i x_i + lambda Delta_i
    omega_i = omega_stance / (exp(-b y_i) + 1) + omega_swing / (exp(b y_i) + 1)
    omega_stance = (1 - beta) / beta * omega_swing
    Delta_i = sum_{j != i} (y_j cos theta_ji - x_j sin theta_ji),  theta_ji = phi_j - phi_i

where phi_i is leg i's desired phase (tripod: RF, RB, LM at 0; RM, LB, LF at pi). The j = i
term of the paper's sum is left out (it is not a coupling). The y signal maps to joint angles
by eq. 4:

    hip   = A1 y
    knee  = A2 (1 - y^2) while dy/dt >= 0 (swing), else 0 (stance)
    ankle = -k1 knee, k1 = A3 / A2

Integration is Heun's method (second-order Runge-Kutta) at the control rate, two derivative
evaluations per step. The coupling term shifts the limit cycle slightly: |y| peaks near 1.02
and the period is 2 pi / sqrt(omega^2 - (2.5 lambda)^2) (2.006 s at omega = pi), matched by
the integration to well under 1% (tested).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

NUM_LEGS = 6
# Side of each leg, in the order RF, RM, RB, LB, LM, LF: +1 right, -1 left (turning scales the sides' strides apart)
LEG_SIDE = np.array([1.0, 1.0, 1.0, -1.0, -1.0, -1.0])
# Desired phase of each leg [rad], legs in order RF, RM, RB, LB, LM, LF: tripods {RF, RB, LM}, {RM, LB, LF}.
TRIPOD_PHASES_RAD: tuple[float, ...] = (0.0, math.pi, 0.0, math.pi, 0.0, math.pi)


@dataclass(frozen=True)
class CPGParams:
    """The paper's CPG parameters (section 2.2)."""

    alpha: float = 10.0  # convergence rate to the limit cycle [1/s]
    mu: float = 1.0  # squared amplitude of the limit cycle
    omega_swing_rad_per_s: float = math.pi
    beta: float = 0.5  # load factor: omega_stance = (1 - beta) / beta * omega_swing
    b: float = 100.0  # sharpness of the stance/swing frequency switch
    coupling: float = 0.1  # lambda
    hip_amplitude_rad: float = 0.45  # A1
    knee_amplitude_rad: float = 1.2  # A2
    ankle_amplitude_rad: float = 1.0  # A3; k1 = A3 / A2
    phases_rad: tuple[float, ...] = TRIPOD_PHASES_RAD

    @property
    def omega_stance_rad_per_s(self) -> float:
        return (1.0 - self.beta) / self.beta * self.omega_swing_rad_per_s

    @property
    def k1(self) -> float:
        return self.ankle_amplitude_rad / self.knee_amplitude_rad if self.knee_amplitude_rad != 0 else 0.0

    def with_gait(self, omega_swing: float, a1: float, a2: float, a3: float) -> "CPGParams":
        """The same CPG with new frequency and amplitudes (what the HRL policy chooses)."""
        return replace(
            self,
            omega_swing_rad_per_s=float(omega_swing),
            hip_amplitude_rad=float(a1),
            knee_amplitude_rad=float(a2),
            ankle_amplitude_rad=float(a3),
        )


def _coupling_matrix(phases: tuple[float, ...]) -> np.ndarray:
    """M[i, j] = exp(-i theta_ji) off the diagonal, so that Delta = Im(M @ z) with z = x + i y."""
    phi = np.asarray(phases, dtype=np.float64)
    theta = phi[None, :] - phi[:, None]  # theta[i, j] = phi_j - phi_i
    return np.exp(-1j * theta) * (1.0 - np.eye(len(phi)))


@dataclass
class _Trajectory:
    """States and outputs of a CPG run from its reset state with fixed parameters."""

    z: list
    dz: list
    angles: list


_MAX_CACHED_STEPS = 20_000
_TRAJECTORIES: dict[tuple, _Trajectory] = {}


class HopfCPG:
    """Six coupled Hopf oscillators and the eq. 4 joint mapping, stepped at a fixed rate.

    The state is kept as z = x + i y, which is eq. 3 unchanged but costs half the array
    operations (the CPG runs inside every environment step). With fixed parameters, a run
    from the reset state is the same deterministic sequence every episode, so it is computed
    once per process and replayed (identical numbers; the open-loop and residual modes never
    change parameters). Changing parameters mid-run (HRL) switches to live integration.
    Returned joint-angle arrays are read-only.
    """

    def __init__(self, params: CPGParams = CPGParams(), dt_s: float = 1.0 / 60.0, max_substep_s: float = 1.0 / 60.0):
        self.params = params
        self.dt_s = float(dt_s)
        self.substeps = max(1, math.ceil(self.dt_s / max_substep_s - 1e-9))
        self._h = self.dt_s / self.substeps
        self._coupling = _coupling_matrix(params.phases_rad)
        self._z = np.zeros(NUM_LEGS, dtype=np.complex128)
        self.reset()

    def reset(self, phase_offset_rad: float = -math.pi / 2) -> None:
        """Start on the limit cycle at the tripod phases (deterministic).

        The default offset puts the first tripod at y = -1, the start of its swing.
        """
        phi = np.asarray(self.params.phases_rad) + phase_offset_rad
        self._z = math.sqrt(self.params.mu) * np.exp(1j * phi)
        self._dz = self._derivative(self._z)
        key = (self.params, self._h, self.substeps, phase_offset_rad)
        if key not in _TRAJECTORIES:
            _TRAJECTORIES[key] = _Trajectory([self._z], [self._dz], [self._angles()])
        self._trajectory: _Trajectory | None = _TRAJECTORIES[key]
        self._k = 0

    def set_params(self, params: CPGParams) -> None:
        if params == self.params:
            return
        if params.phases_rad != self.params.phases_rad:
            self._coupling = _coupling_matrix(params.phases_rad)
        self.params = params
        self._dz = self._derivative(self._z)
        self._trajectory = None  # no longer the cached fixed-parameter run

    @property
    def z(self) -> np.ndarray:
        """Oscillator states x + i y, one per leg."""
        return self._z

    @z.setter
    def z(self, value: np.ndarray) -> None:
        """Set the oscillator states (e.g. to perturb them); integration continues from there."""
        self._z = np.asarray(value, dtype=np.complex128)
        self._dz = self._derivative(self._z)
        self._trajectory = None

    @property
    def x(self) -> np.ndarray:
        return self.z.real

    @property
    def y(self) -> np.ndarray:
        return self.z.imag

    def _derivative(self, z: np.ndarray) -> np.ndarray:
        p = self.params
        y = z.imag
        radial = p.alpha * (p.mu - (z.real * z.real + y * y))
        # |y| stays near 1 on and around the limit cycle, far from exp overflow (b |y| > 709)
        stance_weight = 1.0 / (np.exp(-p.b * y) + 1.0)  # 1 / (e^{-by} + 1)
        omega = p.omega_swing_rad_per_s + (p.omega_stance_rad_per_s - p.omega_swing_rad_per_s) * stance_weight
        return (radial + 1j * omega) * z + 1j * (p.coupling * (self._coupling @ z).imag)

    def step(self) -> np.ndarray:
        """Advance one control step; return the 18 joint targets [rad] (hip, knee, ankle per leg)."""
        traj, k = self._trajectory, self._k + 1
        if traj is not None and k < len(traj.z):
            self._z, self._dz, self._k = traj.z[k], traj.dz[k], k
            return traj.angles[k]
        h = self._h
        z, dz = self._z, self._dz
        for _ in range(self.substeps):  # Heun's method; f(z) at the new state is reused next step
            z_euler = z + h * dz
            z = z + (0.5 * h) * (dz + self._derivative(z_euler))
            dz = self._derivative(z)
        self._z, self._dz, self._k = z, dz, k
        angles = self._angles()
        if traj is not None and k == len(traj.z) and k < _MAX_CACHED_STEPS:
            traj.z.append(z)
            traj.dz.append(dz)
            traj.angles.append(angles)
        return angles

    @property
    def phases_rad(self) -> np.ndarray:
        """Current oscillator phases atan2(y, x) [rad]."""
        return np.angle(self.z)

    def joint_angles(self) -> np.ndarray:
        """Eq. 4 applied to the current state: 18 joint angles [rad]."""
        return self._angles().copy()

    def _angles(self) -> np.ndarray:
        p = self.params
        y = self.z.imag
        out = np.empty((NUM_LEGS, 3))
        out[:, 0] = p.hip_amplitude_rad * y
        out[:, 1] = (p.knee_amplitude_rad * (self._dz.imag >= 0.0)) * (1.0 - y * y)
        out[:, 2] = -p.k1 * out[:, 1]
        out = out.reshape(-1)
        out.flags.writeable = False
        return out
