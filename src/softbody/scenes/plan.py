"""How a scene's run is cut into frames and steps, bounded before it starts.

A run renders (``softbody run``) or samples (``softbody sweep``) one frame every
``1 / fps`` seconds of simulated time, each frame a whole number of steps; runs that
would take more than ``max_steps`` steps or ``max_frames`` frames are refused before
they start (a tiny dt or a tiny ``render.fps`` would otherwise run for hours in silence).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Most simulation steps a run may take unless asked for more (``--max-steps``): 10^8
#: steps are minutes to hours (1 to 100 us a step here for the built-in scenes); more is
#: almost always a dt or a render.fps off by orders of magnitude.
MAX_STEPS = 100_000_000
#: Most frames a run may render unless asked for more (``--max-frames``): 10^5 frames
#: are 55 minutes of video at 30 fps and about half an hour of rendering at 640 x 480;
#: more is almost always a duration or a render.fps off by orders of magnitude.
MAX_FRAMES = 100_000


@dataclass(frozen=True)
class FramePlan:
    """How a run is cut into frames: ``frame_count`` frames after the first (t = 0), each
    ``frame_dt`` = 1 / fps [s] long and of ``steps_per_frame`` steps of ``dt`` [s]; with
    dt = "auto", ``dt`` is the initial stable step and ``steps_per_frame`` the estimate
    it gives (the substeps are re-chosen as the run goes)."""

    frame_count: int
    frame_dt: float
    steps_per_frame: int
    dt: float

    @property
    def total_steps(self) -> int:
        return self.frame_count * self.steps_per_frame


def _count(value: float) -> str:
    """A count for a message: ``12,345`` in full up to 10^15, ``1e+300`` beyond (an
    absurd request should not print 300 digits)."""
    return f"{value:,.0f}" if value < 1e15 else f"{value:.3g}"


def plan_frames(
    duration: float,
    fps: float,
    dt: float,
    *,
    auto: bool = False,
    max_steps: int = MAX_STEPS,
    max_frames: int = MAX_FRAMES,
) -> FramePlan:
    """Frames and steps of a run of ``duration`` [s] at ``fps`` [1/s] with steps of at most
    ``dt`` [s] (the first auto step when ``auto``).

    A frame is exactly 1 / ``fps`` and a whole number of steps: the fewest steps k with
    1 / (fps k) <= dt, each of 1 / (fps k) [s] (``FramePlan.dt``: ``dt`` or less), so that a
    video plays and a USD's time codes run at exactly ``fps``. :class:`ValueError` when
    the run would take more than ``max_steps`` steps or ``max_frames`` frames (computed
    in floating point first, so that an absurd request is refused without building huge
    integers)."""
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"render.fps must be a finite number > 0 frames per second, got {fps!r}")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0 seconds, got {dt!r}")
    frame_dt = 1.0 / fps
    # the relative slack keeps a dt that divides the frame already (1 / (100 * 0.002) is
    # 5 up to round-off) from gaining a step
    per_frame = max(1.0, np.ceil(frame_dt / dt * (1 - 1e-9)))
    step = dt if auto else 1.0 / (fps * per_frame)
    # the run ends on the first frame at or after the requested duration
    frames = max(1.0, np.ceil(duration / frame_dt - 1e-9))
    what = f"dt = {dt:.3g} s" + (" (auto, from the initial stability estimate)" if auto else "")
    if frames > max_frames:
        raise ValueError(
            f"the run would render {_count(frames)} frames ({duration:.6g} s at {fps:.3g} "
            f"frames per second), over the limit of {_count(max_frames)}: shorten the duration "
            "or lower render.fps (or raise the limit with --max-frames)"
        )
    if frames * per_frame > max_steps:
        raise ValueError(
            f"the run would take {_count(frames * per_frame)} steps ({_count(frames)} "
            f"frame{'s' if frames != 1 else ''} of {_count(per_frame)} steps of {what}), over "
            f"the limit of {_count(max_steps)}: raise dt or render.fps, or shorten the duration "
            "(or raise the limit with --max-steps)"
        )
    return FramePlan(int(frames), float(frame_dt), int(per_frame), float(step))
