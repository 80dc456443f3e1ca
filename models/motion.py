"""Vessel attitude models: damped roll, pitch and coupled yaw (Section 2.3, Section 3.1).

Each axis is a constant bias plus a sum of damped modes. One mode is the paper's
free decay released at t0 with zero rate (Eq. 34 for roll; Eq. 41 for pitch is the
same curve, since theta_a cos(x - eps) = theta_0 (cos x + v/n sin x) by Eq. 42):

    a(t) = A exp(-v (t - t0)) [cos n1 (t - t0) + (v / n1) sin n1 (t - t0)]

with n1 the damped circular frequency (Eq. 35) and v the decay rate; v = 0 gives a
steady wave-forced oscillation. Internally a mode is written about a fixed reference
time t_ref as exp(-v (t - t_ref)) [C cos n1 (t - t_ref) + S sin n1 (t - t_ref)]: the
same family, but linear in (C, S), so no two parameter sets give the same curve
(the paper's (A, t0) repeats itself every period). :func:`paper_to_cs` and
:func:`cs_to_paper` convert exactly. Yaw is a slow polynomial trend plus the roll and
pitch oscillations, each scaled by a coupling coefficient, so it shares their
frequencies and decays (the paper fits yaw with the roll model's t0 and n1).

The parameters of a model live in one flat vector laid out by
:class:`AttitudeLayout`; :func:`attitude_function` returns a CasADi Function of
(t, p) used symbolically by the estimators and numerically by the simulator.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .rotations import euler_matrix, unskew

MODE_FIELDS = ("cos_rad", "sin_rad", "omega_rad_s", "decay_1_s")


def damped_mode(t, amplitude, t0, omega, decay):
    """Free decay released at t0 with zero rate (Eqs. 34, 41-42)."""
    tau = t - t0
    return amplitude * ca.exp(-decay * tau) * (
        ca.cos(omega * tau) + decay / omega * ca.sin(omega * tau)
    )


def mode_cs(t, c, s, omega, decay, t_ref):
    """exp(-v (t - t_ref)) [C cos n1 (t - t_ref) + S sin n1 (t - t_ref)]: Eq. 34 about t_ref."""
    tau = t - t_ref
    return ca.exp(-decay * tau) * (c * ca.cos(omega * tau) + s * ca.sin(omega * tau))


def paper_to_cs(amplitude, t0, omega, decay, t_ref):
    """(A, t0) of Eq. 34 -> (C, S) about t_ref, exactly."""
    d = t_ref - t0
    g = amplitude * np.exp(-decay * d)
    k = decay / omega
    return g * (np.cos(omega * d) + k * np.sin(omega * d)), g * (-np.sin(omega * d) + k * np.cos(omega * d))


def cs_to_paper(c, s, omega, decay, t_ref):
    """(C, S) about t_ref -> the paper's (phi_0, t_0) with t_0 within half a period of t_ref."""
    eps = np.arctan2(decay, omega)
    delta = np.arctan2(s, c)
    period = 2 * np.pi / omega
    t0 = t_ref + (delta - eps) / omega
    t0 = t_ref + (t0 - t_ref + period / 2) % period - period / 2
    amplitude = np.hypot(c, s) * np.exp(-decay * (t0 - t_ref)) / np.sqrt(1 + (decay / omega) ** 2)
    return amplitude, t0


@dataclass(frozen=True)
class AttitudeLayout:
    """Shape of an attitude model: modes per axis and the yaw trend's order.

    Parameters
    ----------
    n_roll, n_pitch : int
        Number of damped modes of roll and pitch (>= 0).
    yaw_trend_order : int
        Degree of the yaw trend polynomial in (t - t_ref_s).
    t_ref_s : float
        Reference time of the yaw trend (keeps the polynomial well conditioned).
    """

    n_roll: int = 1
    n_pitch: int = 1
    yaw_trend_order: int = 1
    t_ref_s: float = 0.0

    def __post_init__(self):
        for name in ("n_roll", "n_pitch", "yaw_trend_order"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 0:
                raise ValueError(f"AttitudeLayout.{name}: expected an integer >= 0, got {value!r}")

    @property
    def size(self) -> int:
        """Length of the flat parameter vector."""
        return 4 * self.n_roll + 1 + 4 * self.n_pitch + 1 + (self.yaw_trend_order + 1) + self.n_roll + self.n_pitch

    def slices(self) -> dict[str, slice]:
        """Where each block sits in the flat vector."""
        out, k = {}, 0
        for name, n in (
            ("roll_modes", 4 * self.n_roll),
            ("roll_bias", 1),
            ("pitch_modes", 4 * self.n_pitch),
            ("pitch_bias", 1),
            ("yaw_trend", self.yaw_trend_order + 1),
            ("yaw_coupling", self.n_roll + self.n_pitch),
        ):
            out[name] = slice(k, k + n)
            k += n
        return out


@dataclass(frozen=True)
class AttitudeParams:
    """Numbers of one attitude model; ``pack``/``unpack`` map to the flat vector.

    roll_modes and pitch_modes are (n, 4) arrays of (C_rad, S_rad, omega_rad_s,
    decay_1_s) about t_ref_s (see :func:`mode_cs`); yaw_trend holds polynomial coefficients in
    (t - t_ref_s), lowest order first; yaw_coupling scales each roll mode then each
    pitch mode into the yaw oscillation.
    """

    roll_modes: np.ndarray
    roll_bias: float
    pitch_modes: np.ndarray
    pitch_bias: float
    yaw_trend: np.ndarray
    yaw_coupling: np.ndarray
    t_ref_s: float = 0.0

    @property
    def layout(self) -> AttitudeLayout:
        return AttitudeLayout(
            n_roll=int(np.shape(self.roll_modes)[0]),
            n_pitch=int(np.shape(self.pitch_modes)[0]),
            yaw_trend_order=int(len(self.yaw_trend) - 1),
            t_ref_s=float(self.t_ref_s),
        )

    def pack(self) -> np.ndarray:
        lay = self.layout
        if len(self.yaw_coupling) != lay.n_roll + lay.n_pitch:
            raise ValueError(
                f"yaw_coupling: expected {lay.n_roll + lay.n_pitch} values (one per roll and pitch mode), "
                f"got {len(self.yaw_coupling)}"
            )
        return np.concatenate(
            [
                np.reshape(self.roll_modes, -1),
                [self.roll_bias],
                np.reshape(self.pitch_modes, -1),
                [self.pitch_bias],
                np.asarray(self.yaw_trend, dtype=float),
                np.asarray(self.yaw_coupling, dtype=float),
            ]
        ).astype(float)

    @classmethod
    def unpack(cls, p, layout: AttitudeLayout) -> "AttitudeParams":
        p = np.asarray(p, dtype=float).reshape(-1)
        if p.size != layout.size:
            raise ValueError(f"attitude parameters: expected {layout.size} values for {layout}, got {p.size}")
        s = layout.slices()
        return cls(
            roll_modes=p[s["roll_modes"]].reshape(layout.n_roll, 4),
            roll_bias=float(p[s["roll_bias"]][0]),
            pitch_modes=p[s["pitch_modes"]].reshape(layout.n_pitch, 4),
            pitch_bias=float(p[s["pitch_bias"]][0]),
            yaw_trend=p[s["yaw_trend"]].copy(),
            yaw_coupling=p[s["yaw_coupling"]].copy(),
            t_ref_s=layout.t_ref_s,
        )

    def to_dict(self) -> dict:
        """JSON-ready description per axis; each mode also in the paper's (phi_0, t_0) form."""

        def modes(rows):
            out = []
            for m in rows:
                d = dict(zip(MODE_FIELDS, map(float, m)))
                a, t0 = cs_to_paper(*m, self.t_ref_s)
                d.update(paper_amplitude_rad=float(a), paper_t0_s=float(t0))
                out.append(d)
            return out

        return {
            "t_ref_s": float(self.t_ref_s),
            "roll": {"bias_rad": self.roll_bias, "modes": modes(self.roll_modes)},
            "pitch": {"bias_rad": self.pitch_bias, "modes": modes(self.pitch_modes)},
            "yaw": {
                "trend_coefficients": [float(c) for c in self.yaw_trend],
                "coupling": [float(c) for c in self.yaw_coupling],
            },
        }

    @classmethod
    def from_dict(cls, d: dict) -> "AttitudeParams":
        def modes(axis):
            rows = [[m[f] for f in MODE_FIELDS] for m in d[axis]["modes"]]
            return np.array(rows, dtype=float).reshape(len(rows), 4)

        return cls(
            roll_modes=modes("roll"),
            roll_bias=float(d["roll"]["bias_rad"]),
            pitch_modes=modes("pitch"),
            pitch_bias=float(d["pitch"]["bias_rad"]),
            yaw_trend=np.array(d["yaw"]["trend_coefficients"], dtype=float),
            yaw_coupling=np.array(d["yaw"]["coupling"], dtype=float),
            t_ref_s=float(d.get("t_ref_s", 0.0)),
        )


def attitude_ypr(t, p, layout: AttitudeLayout):
    """Yaw, pitch, roll (3x1 expression) at time t for flat parameters p."""
    s = layout.slices()

    def oscillations(block, n):
        q = p[s[block]]
        return [mode_cs(t, q[4 * k], q[4 * k + 1], q[4 * k + 2], q[4 * k + 3], layout.t_ref_s) for k in range(n)]

    roll_osc = oscillations("roll_modes", layout.n_roll)
    pitch_osc = oscillations("pitch_modes", layout.n_pitch)
    roll = p[s["roll_bias"]][0]
    for osc in roll_osc:
        roll = roll + osc
    pitch = p[s["pitch_bias"]][0]
    for osc in pitch_osc:
        pitch = pitch + osc
    trend = p[s["yaw_trend"]]
    dt = t - layout.t_ref_s
    yaw = sum(trend[k] * dt**k for k in range(layout.yaw_trend_order + 1))
    coupling = p[s["yaw_coupling"]]
    for k, osc in enumerate(roll_osc + pitch_osc):
        yaw = yaw + coupling[k] * osc
    return ca.vertcat(yaw, pitch, roll)


def attitude_function(layout: AttitudeLayout, sym=ca.SX) -> ca.Function:
    """CasADi Function ``attitude(t, p) -> (ypr, Lambda, dLambda_dt, Omega, omega)``.

    Lambda (Eq. 7) maps body to Earth; dLambda_dt is its exact time derivative by
    algorithmic differentiation; Omega = dLambda/dt Lambda^T (Eq. 32) is the
    Earth-frame angular velocity tensor and omega its axial vector (Earth frame).
    """
    t = sym.sym("t")
    p = sym.sym("p", layout.size)
    ypr = attitude_ypr(t, p, layout)
    Lam = euler_matrix(ypr[0], ypr[1], ypr[2])
    dLam = ca.reshape(ca.jacobian(ca.vec(Lam), t), 3, 3)
    Omega = ca.mtimes(dLam, Lam.T)
    omega = unskew(Omega)
    return ca.Function(
        "attitude",
        [t, p],
        [ypr, Lam, dLam, Omega, omega],
        ["t", "p"],
        ["ypr", "Lambda", "dLambda_dt", "Omega", "omega"],
    )


def stack_matrices(block: np.ndarray, n: int) -> np.ndarray:
    """(3, 3n) horizontally mapped CasADi output -> (n, 3, 3)."""
    return np.asarray(block).reshape(3, n, 3).transpose(1, 0, 2)


def evaluate_attitude(params: AttitudeParams, times) -> dict[str, np.ndarray]:
    """Numeric attitude at many times: ypr (n,3), Lambda, dLambda_dt, Omega (n,3,3), omega (n,3)."""
    times = np.asarray(times, dtype=float).reshape(-1)
    n = times.size
    fun = attitude_function(params.layout).map(n)
    ypr, Lam, dLam, Om, om = fun(times[None, :], params.pack())
    return {
        "ypr": np.asarray(ypr).T,
        "Lambda": stack_matrices(Lam, n),
        "dLambda_dt": stack_matrices(dLam, n),
        "Omega": stack_matrices(Om, n),
        "omega": np.asarray(om).T,
    }
