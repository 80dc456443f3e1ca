"""TRDI coordinate frames, inverted in float64: beam <- instrument <- ship <- Earth.

Conventions (TRDI "ADCP Coordinate Transformation", P/N 951-6079-00):

- Instrument frame (down-looking head): X toward beam 2, Y toward beam 3, Z up
  (beams point down, along -Z). Beam velocities are positive toward the transducer.
- Earth frame: E, N, U. Ship frame: X starboard, Y bow, Z up.
- ``M(H, P, R)`` maps instrument to Earth (or ship, with H the alignment EA):
  heading H clockwise from north about -Z, then pitch P about X (bow up positive),
  then roll R about Y (starboard down positive). Angles in radians.
- Internal tilt sensors measure Tilt1, not the gimbal pitch: P = atan(tan(Tilt1) cos(Tilt2)).

Case frames (``case-format.md``): transducer x_t toward case beam 2, y_t toward case
beam 3, z_t out of the face (down). With A = [[0,1,0],[1,0,0],[0,0,-1]] (swap X and Y,
flip Z; A = A^-1), case_t = A inst and NED = A ENU, so A M(H,P,R) A equals the case's
Rz(H) Ry(P) Rx(R): the case Euler angles are exactly (H, P, R), and case beams
1, 2, 3, 4 are RDI beams 4, 3, 2, 1.
"""

from __future__ import annotations

import numpy as np

SWAP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
CASE_FROM_RDI_BEAM = (3, 2, 1, 0)  # case beam i is RDI beam CASE_FROM_RDI_BEAM[i] + 1
BAD_VELOCITY_MM_S = -32768


def rdi_matrix(h, p, r) -> np.ndarray:
    """TRDI rotation M (instrument -> Earth ENU) for arrays of angles in radians, (n, 3, 3)."""
    h, p, r = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (h, p, r))
    ch, sh, cp, sp, cr, sr = np.cos(h), np.sin(h), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
    m = np.empty(h.shape + (3, 3))
    m[:, 0, 0] = ch * cr + sh * sp * sr
    m[:, 0, 1] = sh * cp
    m[:, 0, 2] = ch * sr - sh * sp * cr
    m[:, 1, 0] = -sh * cr + ch * sp * sr
    m[:, 1, 1] = ch * cp
    m[:, 1, 2] = -sh * sr - ch * sp * cr
    m[:, 2, 0] = -cp * sr
    m[:, 2, 1] = sp
    m[:, 2, 2] = cp * cr
    return m


def gimbal_pitch(tilt1_rad, tilt2_rad) -> np.ndarray:
    """Gimbal pitch from the internal tilt sensor: atan(tan(Tilt1) cos(Tilt2)), radians."""
    return np.arctan(np.tan(tilt1_rad) * np.cos(tilt2_rad))


def beam_to_instrument_matrix(beam_angle_rad: float, convex: bool = True) -> np.ndarray:
    """TRDI 4x4 matrix: (b1, b2, b3, b4) -> (X, Y, Z, error velocity)."""
    s, c = np.sin(beam_angle_rad), np.cos(beam_angle_rad)
    a, b = 1.0 / (2.0 * s), 1.0 / (4.0 * c)
    d = a / np.sqrt(2.0)
    k = 1.0 if convex else -1.0
    return np.array([[k * a, -k * a, 0.0, 0.0],
                     [0.0, 0.0, -k * a, k * a],
                     [b, b, b, b],
                     [d, d, -d, -d]])


def to_beam(vel4: np.ndarray, coord_sys: str, beam_angle_rad: float, convex: bool = True,
            rotation: np.ndarray | None = None) -> np.ndarray:
    """Per-beam radial velocities (RDI beam order) from 4-component TRDI velocities, (n, 4).

    Parameters
    ----------
    vel4 : (n, 4) array
        Velocities as recorded: beams 1-4 (``beam``), or three axes and the error
        velocity (``inst``, ``ship``, ``earth``), m/s.
    coord_sys : str
        ``beam``, ``inst``, ``ship`` or ``earth``.
    rotation : (n, 3, 3) array
        The matrix the instrument applied (instrument -> ship or Earth); required for
        ``ship`` and ``earth``. Its transpose undoes levelling, alignment and heading.
    """
    vel4 = np.asarray(vel4, dtype=np.float64)
    if coord_sys == "beam":
        return vel4.copy()
    if coord_sys not in ("inst", "ship", "earth"):
        raise ValueError(f"coord_sys: expected one of beam, inst, ship, earth, got {coord_sys!r}")
    xyz = vel4[:, :3]
    if coord_sys in ("ship", "earth"):
        if rotation is None:
            raise ValueError(f"rotation: required to undo {coord_sys} coordinates")
        xyz = np.einsum("nji,nj->ni", rotation, xyz)  # M^T v
    inst4 = np.column_stack([xyz, vel4[:, 3]])
    return inst4 @ np.linalg.inv(beam_to_instrument_matrix(beam_angle_rad, convex)).T


def beam_to_earth(beams: np.ndarray, beam_angle_rad: float, rotation: np.ndarray, convex: bool = True) -> np.ndarray:
    """The instrument's forward transform: RDI beams (n, 4) -> Earth (E, N, U, error), (n, 4)."""
    inst4 = np.asarray(beams, dtype=np.float64) @ beam_to_instrument_matrix(beam_angle_rad, convex).T
    xyz = np.einsum("nij,nj->ni", rotation, inst4[:, :3])
    return np.column_stack([xyz, inst4[:, 3]])


def case_beams(rdi_beams: np.ndarray) -> np.ndarray:
    """Reorder RDI beams 1-4 into case beams 1-4 (last axis)."""
    return np.asarray(rdi_beams)[..., list(CASE_FROM_RDI_BEAM)]
