"""The ball drop's checks, shared by softbody's side of a peer race and the peer's child
script (which runs in its own Python with NumPy only, so this module imports nothing else).

A drop is a sequence of frames; after each, the centre-of-mass height [m] and the enclosed
volume [m^3] are recorded. It is valid (as ``benchmarks/ball_drop.py`` checks it) when the
volume stays within VOLUME_RANGE of its start every frame, the centre of mass rises at
least MIN_REBOUND after its lowest point, and at the end the kinetic energy of the motion
relative to the centre of mass is below RESTING_SHARE of the drop energy m g h (a ball
shaking from too coarse a step fails). A race entry also asks for a rebound of at least
RACE_REBOUND (issue 33: the bounce kept).
"""

from __future__ import annotations

import numpy as np

#: every frame's volume / start volume must lie strictly inside this range
VOLUME_RANGE = (0.7, 1.5)
#: the least rise [m] of the centre of mass after its lowest point for a bounce
MIN_REBOUND = 0.05
#: the largest internal kinetic energy at the end, as a share of the drop energy
RESTING_SHARE = 0.05
#: the rebound [m] a race entry needs (the bounce kept)
RACE_REBOUND = 0.9


def mesh_volume(positions: np.ndarray, faces: np.ndarray) -> float:
    """Volume [m^3] enclosed by a closed, outward-wound triangle mesh: the divergence
    theorem, sum over faces of x0 . (x1 x x2) / 6. positions (V, 3) [m], faces (F, 3)."""
    x = positions[faces]
    return float(np.einsum("ij,ij->", x[:, 0], np.cross(x[:, 1], x[:, 2])) / 6.0)


def center_of_mass_height(positions: np.ndarray, masses: np.ndarray, axis: int = 1) -> float:
    """Height [m] of the centre of mass along ``axis``. positions (V, 3) [m], masses (V,)
    [kg]."""
    return float(masses @ positions[:, axis] / masses.sum())


def internal_kinetic_energy(velocities: np.ndarray, masses: np.ndarray) -> float:
    """Kinetic energy [J] of the motion relative to the centre of mass. velocities (V, 3)
    [m/s], masses (V,) [kg]."""
    m = masses[:, None]
    v = velocities - (m * velocities).sum(axis=0) / m.sum()
    return 0.5 * float((m * v**2).sum())


def rebound(heights: np.ndarray) -> float:
    """How far [m] the centre of mass rises after its lowest point: the highest height
    after the lowest frame minus the lowest. heights (frames,) [m]."""
    heights = np.asarray(heights, dtype=float)
    bottom = int(np.argmin(heights))
    return float(heights[bottom:].max() - heights[bottom])


def drop_verdict(
    heights: np.ndarray,
    volumes: np.ndarray,
    resting_energy: float,
    drop_energy: float,
    *,
    race_rebound: float = RACE_REBOUND,
) -> dict:
    """The checks of a drop (module docstring). heights (frames,) [m] and volumes
    (frames,) [m^3] after each frame, the start volume first (frame 0, before any step);
    resting_energy [J] the internal kinetic energy at the end; drop_energy m g h [J].
    Returns the rebound [m], the volume ratio range (both None where a value is not
    finite: the drop blew up), ``valid`` (the drop's checks) and ``ok`` (valid and
    rebounding at least ``race_rebound``)."""
    volumes = np.asarray(volumes, dtype=float)
    if volumes.size < 2 or len(heights) != volumes.size:
        raise ValueError("a drop needs its start and a frame, and as many heights as volumes")
    ratios = volumes[1:] / volumes[0]
    finite = bool(np.isfinite(ratios).all() and np.isfinite(heights).all())
    # a drop that blew up has no rebound or range to report (JSON has no NaN)
    low, high = (float(ratios.min()), float(ratios.max())) if finite else (None, None)
    rise = rebound(heights) if finite else None
    resting_finite = bool(np.isfinite(resting_energy))
    valid = (
        finite
        and resting_finite
        and bool(
            VOLUME_RANGE[0] < low
            and high < VOLUME_RANGE[1]
            and rise > MIN_REBOUND
            and resting_energy < RESTING_SHARE * drop_energy
        )
    )
    return {
        "rebound_m": rise,
        "volume_ratio_range": [low, high],
        "internal_kinetic_energy_j": float(resting_energy) if resting_finite else None,
        "final_height_m": float(heights[-1]) if finite else None,
        "valid": valid,
        "ok": bool(valid and rise >= race_rebound),
    }
