"""The Hopf CPG (paper eqs 1-4): limit cycle amplitude and period, tripod phases, joint mapping."""

from __future__ import annotations

import ast
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hexbench.world.cpg import NUM_LEGS, TRIPOD_PHASES_RAD, CPGParams, HopfCPG

CONTROL_DT_S = 1.0 / 60.0
TRIPOD_A = (0, 2, 4)  # RF, RB, LM
TRIPOD_B = (1, 3, 5)  # RM, LB, LF


def run(cpg: HopfCPG, seconds: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step `cpg` for `seconds`; return (t [s], y (steps, 6), joint angles (steps, 18))."""
    n = round(seconds / cpg.dt_s)
    ys, angles = np.empty((n, NUM_LEGS)), np.empty((n, 3 * NUM_LEGS))
    for k in range(n):
        angles[k] = cpg.step()
        ys[k] = cpg.y
    return np.arange(1, n + 1) * cpg.dt_s, ys, angles


def upward_zero_crossings_s(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Times [s] where y crosses 0 upwards, linearly interpolated between samples."""
    k = np.nonzero((y[:-1] < 0) & (y[1:] >= 0))[0]
    return t[k] + (t[k + 1] - t[k]) * (-y[k]) / (y[k + 1] - y[k])


def relative_phase_error_rad(cpg: HopfCPG) -> float:
    """Largest deviation of any leg's phase (relative to RF) from the tripod pattern [rad]."""
    rel = cpg.phases_rad - np.asarray(TRIPOD_PHASES_RAD)
    return float(np.max(np.abs(np.angle(np.exp(1j * (rel - rel[0]))))))


def test_paper_parameters() -> None:
    p = CPGParams()
    assert (p.alpha, p.mu, p.beta, p.b, p.coupling) == (10.0, 1.0, 0.5, 100.0, 0.1)
    assert p.omega_swing_rad_per_s == pytest.approx(math.pi)
    assert p.omega_stance_rad_per_s == pytest.approx(math.pi)  # (1 - 0.5) / 0.5 * pi
    assert (p.hip_amplitude_rad, p.knee_amplitude_rad, p.ankle_amplitude_rad) == (0.45, 1.2, 1.0)
    assert p.k1 == pytest.approx(1.0 / 1.2)
    assert p.phases_rad == (0.0, math.pi, 0.0, math.pi, 0.0, math.pi)


def coupled_amplitude_bounds(p: CPGParams) -> tuple[float, float]:
    """Bounds on the limit-cycle radius of the coupled tripod network.

    In the tripod pattern every other leg j adds +y_i to Delta_i (same tripod: y_j = y_i; other
    tripod: -y_j = y_i), so Delta_i = 5 y_i and eq. 3's radial equation becomes
    dr/dt = alpha (mu - r^2) r + 5 lambda r sin^2(phi): the radius stays between sqrt(mu) and
    sqrt(mu + 5 lambda / alpha) (1.0 and 1.025 with the paper's numbers).
    """
    return math.sqrt(p.mu), math.sqrt(p.mu + (NUM_LEGS - 1) * p.coupling / p.alpha)


def coupled_period_s(p: CPGParams) -> float:
    """Period of the coupled tripod network with beta = 0.5.

    The same Delta_i = 5 y_i term changes the phase speed to omega + 2.5 lambda sin(2 phi), so the
    period is the integral of dphi / (omega + c sin 2phi) = 2 pi / sqrt(omega^2 - c^2), c = 2.5 lambda:
    0.3% longer than 2 pi / omega at omega = pi, 1.3% longer at pi / 2.
    """
    c = (NUM_LEGS - 1) * p.coupling / 2
    return 2 * math.pi / math.sqrt(p.omega_swing_rad_per_s ** 2 - c ** 2)


def test_uncoupled_limit_cycle_amplitude_is_sqrt_mu() -> None:
    cpg = HopfCPG(CPGParams(coupling=0.0), dt_s=CONTROL_DT_S)
    _, ys, _ = run(cpg, 10.0)
    np.testing.assert_allclose(np.hypot(cpg.x, cpg.y), 1.0, atol=0.002)
    late = ys[len(ys) // 2:]
    np.testing.assert_allclose(late.max(axis=0), 1.0, atol=0.002)
    np.testing.assert_allclose(late.min(axis=0), -1.0, atol=0.002)


@pytest.mark.parametrize("mu", [1.0, 0.25, 2.0])
def test_coupled_limit_cycle_amplitude(mu: float) -> None:
    p = CPGParams(mu=mu)
    low, high = coupled_amplitude_bounds(p)
    cpg = HopfCPG(p, dt_s=CONTROL_DT_S)
    _, ys, _ = run(cpg, 10.0)
    late = np.abs(ys[len(ys) // 2:]).max(axis=0)
    assert np.all(late >= low) and np.all(late <= high), (late, low, high)
    radius = np.abs(cpg.z)
    assert np.all(radius >= low - 1e-3) and np.all(radius <= high + 1e-3)


def test_amplitude_recovers_from_perturbation() -> None:
    """Started well off the limit cycle, the radius converges back within 3 s (rate alpha)."""
    cpg = HopfCPG(dt_s=CONTROL_DT_S)
    low, high = coupled_amplitude_bounds(cpg.params)
    cpg.z = cpg.z * np.array([0.3, 1.6, 0.5, 1.4, 0.8, 1.2])
    cpg.set_params(cpg.params)
    run(cpg, 3.0)
    radius = np.abs(cpg.z)
    assert np.all(radius >= low - 0.005) and np.all(radius <= high + 0.005), radius


@pytest.mark.parametrize("omega_swing", [math.pi, math.pi / 2, 0.75 * math.pi])
def test_uncoupled_period_is_two_pi_over_omega(omega_swing: float) -> None:
    """With beta = 0.5 both half-cycles run at omega, so the period is 2 pi / omega (2 s for pi)."""
    cpg = HopfCPG(CPGParams(omega_swing_rad_per_s=omega_swing, coupling=0.0), dt_s=CONTROL_DT_S)
    t, ys, _ = run(cpg, 20.0)
    for leg in range(NUM_LEGS):
        periods = np.diff(upward_zero_crossings_s(t, ys[:, leg]))
        assert len(periods) >= 4
        np.testing.assert_allclose(periods, 2 * math.pi / omega_swing, rtol=0.002)


@pytest.mark.parametrize("omega_swing", [math.pi, math.pi / 2, 0.75 * math.pi])
def test_coupled_period(omega_swing: float) -> None:
    """The paper's network (lambda 0.1): period 2 pi / sqrt(omega^2 - (2.5 lambda)^2), ~2 s at omega = pi."""
    p = CPGParams(omega_swing_rad_per_s=omega_swing)
    cpg = HopfCPG(p, dt_s=CONTROL_DT_S)
    t, ys, _ = run(cpg, 20.0)
    for leg in range(NUM_LEGS):
        periods = np.diff(upward_zero_crossings_s(t, ys[:, leg]))
        assert len(periods) >= 4
        np.testing.assert_allclose(periods, coupled_period_s(p), rtol=0.002)
    if omega_swing == math.pi:
        np.testing.assert_allclose(periods, 2.0, rtol=0.005)


def test_load_factor_sets_time_share_of_the_fast_and_slow_half_cycles() -> None:
    """Eq. 2: omega is omega_stance while y > 0 and omega_swing while y < 0, so with beta = 0.75
    the y > 0 half takes 3 s and the y < 0 half 1 s: 75% of a 4 s period."""
    cpg = HopfCPG(CPGParams(beta=0.75), dt_s=CONTROL_DT_S)
    run(cpg, 8.0)  # settle
    t, ys, _ = run(cpg, 16.0)
    y = ys[:, 0]
    periods = np.diff(upward_zero_crossings_s(t, y))
    np.testing.assert_allclose(periods, math.pi / (math.pi / 3) + math.pi / math.pi, rtol=0.02)
    assert np.mean(y > 0) == pytest.approx(0.75, abs=0.02)


def test_tripod_phase_relations_hold_on_the_limit_cycle() -> None:
    cpg = HopfCPG(dt_s=CONTROL_DT_S)
    _, ys, _ = run(cpg, 20.0)
    for tripod in (TRIPOD_A, TRIPOD_B):  # legs of one tripod move together ...
        for leg in tripod[1:]:
            np.testing.assert_allclose(ys[:, leg], ys[:, tripod[0]], atol=1e-6)
    np.testing.assert_allclose(ys[:, TRIPOD_B[0]], -ys[:, TRIPOD_A[0]], atol=1e-6)  # ... half a cycle apart
    assert relative_phase_error_rad(cpg) < 1e-6


def test_coupling_pulls_perturbed_phases_back_to_the_tripod_pattern() -> None:
    cpg = HopfCPG(dt_s=CONTROL_DT_S)
    offsets = np.random.default_rng(7).uniform(-0.5, 0.5, NUM_LEGS)
    cpg.z = cpg.z * np.exp(1j * offsets)
    cpg.set_params(cpg.params)
    start_error = relative_phase_error_rad(cpg)
    assert start_error > 0.3
    run(cpg, 20.0)
    assert relative_phase_error_rad(cpg) < 0.01 * start_error


def test_without_coupling_phase_errors_persist() -> None:
    """The convergence above is the coupling's work (lambda Delta of eq. 3), not the integrator's."""
    cpg = HopfCPG(CPGParams(coupling=0.0), dt_s=CONTROL_DT_S)
    cpg.z = cpg.z * np.exp(1j * np.array([0.0, 0.4, -0.3, 0.2, 0.0, -0.4]))
    cpg.set_params(cpg.params)
    start_error = relative_phase_error_rad(cpg)
    run(cpg, 20.0)
    assert relative_phase_error_rad(cpg) == pytest.approx(start_error, abs=1e-3)


def test_joint_mapping_is_eq_4() -> None:
    p = CPGParams()
    cpg = HopfCPG(p, dt_s=CONTROL_DT_S)
    for _ in range(300):
        angles = cpg.step().reshape(NUM_LEGS, 3)
        y, dy = cpg.y, cpg._dz.imag
        np.testing.assert_allclose(angles[:, 0], p.hip_amplitude_rad * y, atol=1e-12)
        swing = dy >= 0
        np.testing.assert_allclose(angles[swing, 1], p.knee_amplitude_rad * (1 - y[swing] ** 2), atol=1e-12)
        np.testing.assert_array_equal(angles[~swing, 1], 0.0)
        np.testing.assert_allclose(angles[:, 2], -p.k1 * angles[:, 1], atol=1e-12)


def test_joint_angle_ranges_and_swing_timing() -> None:
    """Hip sweeps +-A1 |y|max; the knee lifts (up to A2) only while y rises, i.e. while the hip
    swings forward; the ankle folds by k1 times the knee. |y| peaks slightly above 1 (coupling,
    see `coupled_amplitude_bounds`), so the knee dips a few hundredths of a radian below 0
    around the turning points, as eq. 4 prescribes."""
    p = CPGParams()
    cpg = HopfCPG(p, dt_s=CONTROL_DT_S)
    _, ys, angles = run(cpg, 10.0)
    y_max = np.abs(ys).max()
    a = angles.reshape(len(angles), NUM_LEGS, 3)
    assert np.abs(a[:, :, 0]).max() == pytest.approx(p.hip_amplitude_rad * y_max, rel=1e-9)
    assert a[:, :, 0].max() == pytest.approx(0.45, rel=0.03)
    assert a[:, :, 0].min() == pytest.approx(-0.45, rel=0.03)
    assert a[:, :, 1].max() == pytest.approx(1.2, abs=0.005)
    assert a[:, :, 1].min() >= p.knee_amplitude_rad * (1 - y_max ** 2) - 1e-12
    assert a[:, :, 1].min() > -0.06
    assert a[:, :, 2].min() == pytest.approx(-1.0, abs=0.005)
    hip_rising = np.diff(a[:, :, 0], axis=0) > 0
    knee_up = a[1:, :, 1] > 0.05
    assert np.all(hip_rising[knee_up])  # a lifted foot always moves forward
    # the two tripods alternate: while one is lifted, the other stands
    lifted_a = (a[:, TRIPOD_A, 1] > 0.05).all(axis=1)
    lifted_b = (a[:, TRIPOD_B, 1] > 0.05).all(axis=1)
    assert lifted_a.any() and lifted_b.any()
    assert not np.any(lifted_a & lifted_b)
    assert np.mean(a[:, TRIPOD_A, 1] != 0.0) == pytest.approx(0.5, abs=0.02)  # half the cycle in swing (dy >= 0)


def test_reset_starts_first_tripod_at_the_start_of_its_swing() -> None:
    cpg = HopfCPG(dt_s=CONTROL_DT_S)
    np.testing.assert_allclose(cpg.y[list(TRIPOD_A)], -1.0, atol=1e-12)
    np.testing.assert_allclose(cpg.y[list(TRIPOD_B)], 1.0, atol=1e-12)
    run(cpg, 0.25)
    now = cpg.joint_angles().reshape(NUM_LEGS, 3)
    assert np.all(now[list(TRIPOD_A), 1] > 0.1)  # tripod A lifted and swinging forward
    assert np.all(now[list(TRIPOD_B), 1] == 0.0)  # tripod B in stance


def test_same_parameters_give_identical_signals() -> None:
    a, b = HopfCPG(dt_s=CONTROL_DT_S), HopfCPG(dt_s=CONTROL_DT_S)
    np.testing.assert_array_equal(run(a, 5.0)[2], run(b, 5.0)[2])
    a.reset()
    b.reset()
    np.testing.assert_array_equal(run(a, 1.0)[2], run(b, 1.0)[2])


def test_with_gait_changes_frequency_and_amplitudes() -> None:
    gait = CPGParams().with_gait(math.pi / 2, 0.3, 0.8, -0.4)
    assert gait.omega_swing_rad_per_s == pytest.approx(math.pi / 2)
    assert (gait.hip_amplitude_rad, gait.knee_amplitude_rad, gait.ankle_amplitude_rad) == (0.3, 0.8, -0.4)
    assert gait.k1 == pytest.approx(-0.5)
    cpg = HopfCPG(dt_s=CONTROL_DT_S)
    cpg.set_params(gait)
    t, ys, angles = run(cpg, 12.0)
    np.testing.assert_allclose(np.diff(upward_zero_crossings_s(t, ys[:, 0])), coupled_period_s(gait), rtol=0.002)
    assert np.abs(angles[:, 0::3]).max() == pytest.approx(0.3 * np.abs(ys).max(), rel=1e-9)


def test_cpg_substeps_when_the_control_step_is_long() -> None:
    """A 0.1 s control step is split into substeps no longer than 1/60 s and keeps the period."""
    cpg = HopfCPG(dt_s=0.1)
    assert cpg.substeps == 6
    t, ys, _ = run(cpg, 20.0)
    np.testing.assert_allclose(np.diff(upward_zero_crossings_s(t, ys[:, 0])), coupled_period_s(cpg.params), rtol=0.002)


def test_cpg_module_imports_only_numpy_and_the_standard_library() -> None:
    path = Path(__file__).resolve().parents[1] / "hexbench" / "world" / "cpg.py"
    imported = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            imported |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            imported.add(node.module.split(".")[0])
    assert imported <= {"__future__", "math", "dataclasses", "numpy"}, imported
    # and loading it alone pulls in no physics engine
    code = (
        "import importlib.util, sys\n"
        f"spec = importlib.util.spec_from_file_location('cpg_alone', {str(path)!r})\n"
        "mod = importlib.util.module_from_spec(spec); sys.modules['cpg_alone'] = mod\n"
        "spec.loader.exec_module(mod)\n"
        "mod.HopfCPG().step()\n"
        "assert 'pybullet' not in sys.modules, 'pybullet was imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
